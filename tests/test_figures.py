"""The figures users get: units on every axis, integer signals on integer ticks,
each connected signal drawn once, a Hunt-Crossley loop whose loading branch is seen above the
unloading one, and a HopController figure that shows its law at work.

The figures are built by the master scripts from runs of the *built* FMUs (fmpy); the checks
read what was drawn (matplotlib artists) against independent facts: the units of the FMU's
modelDescription, the elastic part K delta^n of the Hunt-Crossley law, the README's control
law and the energy of a lossless spring-mass hop.
"""
import numpy as np
import pytest
from fmpy import read_model_description

from support import DIST, all_fmus

from pogofmu import experiments
from pogofmu import ssp

import matplotlib  # noqa: E402  (a dependency of the project, pyproject.toml)

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


@pytest.fixture(scope="module")
def runs():
    """Each FMU's default experiment as the master script runs it, with its model."""
    out = {}
    for name in all_fmus():
        model = experiments.model_of(DIST / f"{name}.fmu")
        out[name] = (experiments.simulate_default(DIST / f"{name}.fmu", model=model), model)
    return out


def md_units(name):
    md = read_model_description(str(DIST / f"{name}.fmu"))
    return {v.name: (v.unit or (v.declaredType.unit if v.declaredType is not None else None)) or "-"
            for v in md.modelVariables}


def integer_ticks(ax):
    return all(float(t).is_integer() for t in ax.get_yticks())


@pytest.mark.parametrize("name", ["HopController", "Penetrator", "PogoStick", "PogoStickMem", "PogoStickSMA"])
def test_every_panel_has_its_units_and_integer_signals_integer_ticks(name, runs):
    res, model = runs[name]
    units = md_units(name)
    integer = {v.name for v in read_model_description(str(DIST / f"{name}.fmu")).modelVariables
               if v.type == "Integer"}
    figs = experiments.figures(res, model, name)
    try:
        assert len(figs) == len(model.plots)
        for fig, panels in zip(figs, model.plots):
            assert len(fig.axes) == len(panels)
            for ax, panel in zip(fig.axes, panels):
                names = panel[1:3] if panel[0] == "vs" else panel
                label = ax.get_ylabel() + " " + ax.get_xlabel()
                for n in names:  # each signal's unit, as the modelDescription gives it, on its axis
                    assert n in label and f"[{units[n]}]" in label, (n, units[n], label)
                if panel[0] != "vs" and all(n in integer for n in panel):
                    assert integer_ticks(ax), (name, panel, ax.get_yticks())
                    assert len(ax.get_yticks()) >= 2
    finally:
        for fig in figs:
            plt.close(fig)


def test_integer_panels_of_the_sma_stick_had_fractional_ticks_before(runs):
    """Control for the tick check: the same panel without the integer locator gets 0.5 steps."""
    res, model = runs["PogoStickSMA"]
    fig, ax = plt.subplots()
    for n in ("branch", "s"):
        ax.step(res["time"], res[n], where="post")
    fig.canvas.draw()
    assert not integer_ticks(ax)
    plt.close(fig)


def test_penetrator_loop_shows_loading_above_unloading(runs):
    """Loading (delta_dot > 0) and unloading (< 0) in two colours with a legend; every loading
    point lies on or above the elastic curve K delta^n and every unloading point on or below it
    (the Hunt-Crossley damping term has the sign of delta_dot), and an inset shows the two
    branches apart."""
    res, model = runs["Penetrator"]
    md = read_model_description(str(DIST / "Penetrator.fmu"))
    start = {v.name: float(v.start) for v in md.modelVariables if v.causality == "parameter" and v.type == "Real"}
    K, n = start["K"], start["n"]
    figs = experiments.figures(res, model, "Penetrator")
    try:
        [(fig, ax)] = [(f, a) for f in figs for a in f.axes if a.get_xlabel().startswith("delta [")]
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        load = lines["loading (delta_dot > 0)"]
        unload = lines["unloading (delta_dot < 0)"]
        assert load.get_color() != unload.get_color()
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        assert legend == ["loading (delta_dot > 0)", "unloading (delta_dot < 0)"]
        for line, sign in ((load, 1), (unload, -1)):
            d, F = (np.asarray(a, float) for a in line.get_data())
            ok = np.isfinite(d)
            assert ok.sum() > 500  # both branches are drawn, over many samples
            elastic = K * d[ok] ** n
            assert np.all(sign * (F[ok] - elastic) >= -1e-9 * np.maximum(elastic, 1)), sign
            assert np.max(sign * (F[ok] - elastic)) > 0.5  # and the loop is open (> 0.5 N)
        [inset] = ax.child_axes
        assert len(inset.get_lines()) == 2
        x0, x1 = inset.get_xlim()
        assert 0 < x1 - x0 < 0.1 * (np.nanmax(res["delta"]) - 0)  # a real magnification
    finally:
        for fig in figs:
            plt.close(fig)


def test_hop_controller_default_experiment_sweeps_its_law_over_a_hop(runs):
    """The default experiment drives the controller's inputs over lossless spring-mass hops (the
    model's default_input): the inputs are a hop (energy constant, touchdown and liftoff at
    y = x_i, flight a parabola), every phase occurs, and the thrust is the README's law of
    those inputs, non-zero and saturated at F_max only part of the time."""
    from test_ssp import law

    res, model = runs["HopController"]
    p = model.defaults()
    # fmpy holds each input over a step: row k holds u(t_k-1); row 0 (before any step) is dropped
    y, yd, s, F = (res[n][1:] for n in ("y", "ydot", "s", "F_ext"))
    assert set(np.unique(s)) == {0, 1} and set(np.unique(res["phase"])) == {0, 1, 2}
    energy = 0.5 * p["m"] * yd ** 2 + p["m"] * p["g"] * y + s * 0.5 * p["k"] * (y - p["x_i"]) ** 2
    np.testing.assert_allclose(energy, energy[0], rtol=1e-9)
    switch = np.flatnonzero(np.diff(s) != 0)
    assert len(switch) >= 3
    dt = res["time"][1] - res["time"][0]
    for k in switch:  # the leg touches and leaves the ground at its free length
        assert abs(y[k] - p["x_i"]) <= abs(yd[k]) * dt * 1.01
    flight = s == 0
    np.testing.assert_allclose(np.diff(yd)[flight[:-1] & flight[1:]], -p["g"] * dt, rtol=1e-6)
    expected = np.array([law(a, b, c, p) for a, b, c in zip(y, yd, s)])
    np.testing.assert_allclose(F, expected, rtol=1e-12, atol=1e-12)
    on = F > 0
    assert on.mean() > 0.05 and np.all(F <= p["F_max"])
    assert 0 < np.mean(F[on] == p["F_max"]) < 0.5  # the law at work, not a constant


def test_default_input_is_model_data_the_fmu_ignores():
    """The inputs of the default experiment come from the model definition, not from the FMU's
    modelDescription (a plain fmpy run without them sees constant inputs and no thrust)."""
    from support import simulate

    run = simulate("HopController")
    assert np.all(run["F_ext"] == 0)


@pytest.fixture(scope="module")
def ssp_run():
    rec = ssp.simulate(DIST / "SpaceHopper.ssp", parameters="moon", stop_time=4.0, step=1e-3, echo_log=False)
    fig = ssp.figure(rec, "SpaceHopper", rec.connections)
    yield rec, fig
    plt.close(fig)


def test_ssp_figure_draws_each_connected_signal_once(ssp_run):
    """The plant's and the controller's copy of y, ydot, s, F_ext are one line each, labelled
    with both names; no two drawn lines are the same signal."""
    rec, fig = ssp_run
    lines = [ln for ax in fig.axes for ln in ax.get_lines()]
    labels = [ln.get_label() for ln in lines]
    for c in rec.connections:
        src, dst = f"{c.start_element}.{c.start_connector}", f"{c.end_element}.{c.end_connector}"
        assert f"{src} = {dst}" in labels
        assert not any(lb.startswith(dst) for lb in labels)
    data = [tuple(np.asarray(ln.get_ydata(), float).round(12)) for ln in lines]
    assert len(set(data)) == len(data)
    assert len(lines) == len(rec.names) - 2 - len(rec.connections) - 1  # all but time, event, copies, n_events


def test_ssp_figure_units_and_integer_ticks(ssp_run):
    rec, fig = ssp_run
    units = {**{f"PogoStick.{k}": u for k, u in md_units("PogoStick").items()},
             **{f"HopController.{k}": u for k, u in md_units("HopController").items()}}
    fig.canvas.draw()
    for ax in fig.axes:
        [line] = ax.get_lines()
        name = line.get_label().split(" = ")[0]
        assert ax.get_ylabel() == f"{name.split('.')[1]} [{units[name]}]"
        if rec.types[name] != "Real":
            assert integer_ticks(ax), (name, ax.get_yticks())


def test_ssp_figure_of_a_long_run_keeps_every_peak():
    """The figure is drawn from the min/max envelope: for a run longer than the envelope has
    slices, the drawn y keeps the true extremes of every signal (a stride would lose them)."""
    rec = ssp.simulate(DIST / "SpaceHopper.ssp", parameters="earth", stop_time=6.0, step=1e-3, echo_log=False)
    assert rec.rows > 2 * ssp.PLOT_BINS
    fig = ssp.figure(rec, "SpaceHopper", rec.connections)
    try:
        for ax in fig.axes:
            [line] = ax.get_lines()
            name = line.get_label().split(" = ")[0]
            y = np.asarray(line.get_ydata(), float)
            assert len(y) <= 2 * ssp.PLOT_BINS
            assert y.max() == rec[name].max() and y.min() == rec[name].min(), name
        # control: a plain stride (every 3rd sample, what the 6001 rows would need) misses extremes
        names = [ln.get_label().split(" = ")[0] for ax in fig.axes for ln in ax.get_lines()]
        assert any(rec[n][::3].max() != rec[n].max() or rec[n][::3].min() != rec[n].min() for n in names)
    finally:
        plt.close(fig)
