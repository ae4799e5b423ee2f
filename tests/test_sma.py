"""PogoStickSMA.fmu (docs/models.md "PogoStickSMA"): shape-memory-alloy flag leg, through the built FMU.

References are independent of the code under test: the flag's geometry (plateau lines, the
closed-form meeting point and area of a cycle), a solve_ivp model (tests/references.py's
``reference_stick``) with guards in ``x`` instead of the FMU's force differences, and the energy
balance.
"""
import math

import numpy as np
import pytest

from references import scipy_sma
from support import Instance, assert_parameter_rejected, parse_event_log, simulate

NAME = "PogoStickSMA"
M, X_I, G = 1.0, 1.0, 9.81
K1, K2, X1, X3, C = 100.0, 40.0, -0.2, -0.1, 0.5
E0 = M * G * 1.5
TIGHT = {"method": 8, "rel_tol": 1e-12, "abs_tol": 1e-14}
FIRST_CONTACT = ["touchdown", "upper_plateau", "reversal", "lower_plateau", "virgin_line", "liftoff"]


def r_upper(x, k1=K1, k2=K2, x1=X1):
    return k1 * x1 + k2 * (x - x1)


def r_lower(x, k1=K1, k2=K2, x3=X3):
    return k1 * x3 + k2 * (x - x3)


def band(x, k1=K1, k2=K2, x1=X1, x3=X3):
    """The flag: every admissible (x, r_SMA) lies between these two curves."""
    lo = np.maximum(k1 * x, r_upper(x, k1, k2, x1))
    hi = np.maximum(k1 * x, r_lower(x, k1, k2, x3))
    return lo, hi


def sma_run(stop_time, output_interval=1e-3, **params):
    return simulate(NAME, start_values=dict(log_events=1, **params), stop_time=stop_time,
                    output_interval=output_interval)


def xev(e):
    return e["state"]["xbar"] - X_I


def energy(e):
    return M * G * e["state"]["y"] + 0.5 * M * e["state"]["ydot"] ** 2


# ---- the default drop ---------------------------------------------------------------------------

def test_first_contact_runs_the_flag():
    """Defaults: touchdown, upper plateau at x1, reversal, lower plateau at H_l + x3 - x1 (1e-9 m),
    virgin line at x3, liftoff; then the run of docs/models.md "PogoStickSMA" (23 events in 10 s)."""
    run = sma_run(10.0)
    ev = run.events()
    assert [e["name"] for e in ev[:6]] == FIRST_CONTACT
    td, up, rev, low, vir, lo = ev[:6]
    assert td["time"] == pytest.approx(math.sqrt(2 * 0.5 / G), abs=1e-9)
    assert xev(up) == pytest.approx(X1, abs=1e-9)
    H = xev(rev)
    assert abs(rev["state"]["xdot"]) < 1e-9
    assert H == pytest.approx(-0.472, abs=1e-3)  # docs/models.md: "reversal near x = -0.472"
    assert abs(xev(low) - (H + X3 - X1)) <= 1e-9
    assert xev(vir) == pytest.approx(X3, abs=1e-9)
    assert lo["time"] == pytest.approx(0.820, abs=1e-3)
    # outputs: H_l holds the reversal point; branch follows the events
    t = run["time"]
    at = lambda tt: int(np.searchsorted(t, tt))  # noqa: E731 (first sample at or after tt)
    assert run["H_l"][at(rev["time"]) + 1] == pytest.approx(H, abs=1e-15)
    assert run["H_l"][at(rev["time"]) - 1] == 0.0
    for (a, b), branch in zip(zip(ev[:5], ev[1:6]), (0, 1, 0, 2, 0)):
        mid = at(0.5 * (a["time"] + b["time"]))
        assert run["branch"][mid] == branch and run["s"][mid] == 1, (a["name"], b["name"])
    assert run["branch"][at(lo["time"]) + 1] == 0 and run["s"][at(lo["time"]) + 1] == 0
    # the rest of the default experiment (docs/models.md): 3 full flags, a small 4th one, settles
    names = [e["name"] for e in ev]
    assert len(ev) == 23 and run["n_events"][-1] == 23
    assert names[:18] == FIRST_CONTACT * 3 and names[18:] == FIRST_CONTACT[:5]
    assert xev(ev[20]) == pytest.approx(-0.205, abs=1e-3)
    assert run["s"][-1] == 1 and run["branch"][-1] == 0


def test_event_times_agree_with_scipy():
    """Every event of the first 3 s against an independent solve_ivp SMA stick (1e-8 s)."""
    ref = scipy_sma(3.0)
    run = sma_run(3.0, 1e-2, **TIGHT)
    got = run.events()
    assert [e["name"] for e in got] == [n for n, _ in ref]
    assert len(got) >= 12
    for e, (name, t) in zip(got, ref):
        assert abs(e["time"] - t) < 1e-8, (name, e["time"], t)


@pytest.mark.parametrize("c", (0.0, C))
def test_work_per_contact_is_flag_area_plus_dashpot_work(c):
    """Per completed contact the leg absorbs the flag's area (k1 - k2)(x3 - x1)(x1 - H_l), from
    the recorded reversal point, plus the dashpot's work c * integral of xdot^2."""
    stop = 4.0
    run = sma_run(stop, 1e-4, c=c, **TIGHT)
    ev = run.events()
    t, W, xdot = run["time"], run["W_leg"], run["xdot"]
    n_contacts = 0
    for k in range(len(ev) - 5):
        if [e["name"] for e in ev[k:k + 6]] != FIRST_CONTACT:
            continue
        td, rev, lo = ev[k], ev[k + 2], ev[k + 5]
        H = xev(rev)
        area = (K1 - K2) * (X3 - X1) * (X1 - H)
        assert area > 0.1
        i0, i1 = np.searchsorted(t, td["time"]), np.searchsorted(t, lo["time"])
        W_contact = W[i1 + 1] - W[i0 - 1]  # W_leg is frozen in flight
        # the dashpot's work from the sampled xdot (trapezoid, the contact's end points included)
        ts = np.concatenate(([td["time"]], t[i0:i1], [lo["time"]]))
        vs = np.concatenate(([td["state"]["ydot"]], xdot[i0:i1], [lo["state"]["xdot"]]))
        W_dash = c * np.sum(0.5 * (vs[1:] ** 2 + vs[:-1] ** 2) * np.diff(ts))
        assert W_contact == pytest.approx(area + W_dash, rel=1e-6, abs=1e-9)
        assert energy(td) - energy(lo) == pytest.approx(area + W_dash, rel=1e-6, abs=1e-9)
        if c == 0.0:
            assert W_contact == pytest.approx(area, abs=1e-9)
        n_contacts += 1
    assert n_contacts >= 3


def test_energy_balance():
    """E + W_leg = E(0) within 1e-8 E(0) over the default experiment."""
    run = sma_run(10.0, 1e-3, **TIGHT)
    E = 0.5 * M * run["ydot"] ** 2 + M * G * run["y"]
    np.testing.assert_allclose(run["E"], E, rtol=1e-14)
    assert np.max(np.abs(run["E"] + run["W_leg"] - E0)) <= 1e-8 * E0
    assert run["W_leg"][-1] > 0.3 * E0


# ---- forcing: inner loops -------------------------------------------------------------------------

@pytest.mark.parametrize("seed", (1, 2, 3))
def test_random_forcing_makes_inner_loops_inside_the_flag(seed):
    """Standing on the SMA leg, a random piecewise-constant F_ext switching sign drives inner loops:
    every elastic segment has slope k1, every plateau slope k2, and r_SMA = r - c xdot never leaves
    the band between the plateaus; E + W_leg = E(0) + W_ext throughout."""
    c, h = 4.0, 2e-3
    rng = np.random.default_rng(seed)
    inst = Instance(NAME).init(c=c, z_0=0.0, y_0=1.0, xbar_0=1.0, ydot_0=0.0, xdot_0=0.0, log_events=1, **TIGHT)
    E_0 = M * G * 1.0
    rows = []
    try:
        F = -15.0
        while inst.t < 8.0 - 1e-9:
            # alternate loading (pressing down) and unloading (down to a light pull up)
            F = float(rng.uniform(-22.0, -9.0) if F > -8.0 else rng.uniform(-7.0, 3.0))
            inst.set(F_ext=F)
            for _ in range(int(rng.integers(30, 150))):
                inst.step(h)
                rows.append(inst.get("x", "xdot", "r", "branch", "n_events", "s", "E", "W_leg", "W_ext"))
    finally:
        inst.close()
    x, xdot, r, branch, n_ev, s, E, W, Wx = (np.array(col) for col in zip(*rows))
    r_sma = np.where(s == 1, r - c * xdot, 0.0)
    lo, hi = band(x)
    assert np.all(r_sma >= lo - 1e-9) and np.all(r_sma <= hi + 1e-9)
    # every sample lies on the line its latest event put it on: an elastic line starts on the
    # plateau at the reversal / reload point (x of that event, from the log), plateaus are r_U, r_L
    events = parse_event_log(inst.messages)
    assert [e["index"] for e in events] == list(range(1, len(events) + 1))
    for k in np.flatnonzero(s == 1):
        e = events[n_ev[k] - 1] if n_ev[k] else {"name": "virgin_line"}  # starts on the virgin line
        if e["name"] in ("touchdown", "virgin_line"):
            line = K1 * x[k]
        elif e["name"] == "reversal":
            line = r_upper(xev(e)) + K1 * (x[k] - xev(e))
        elif e["name"] == "reload":
            line = r_lower(xev(e)) + K1 * (x[k] - xev(e))
        else:
            line = r_upper(x[k]) if e["name"] == "upper_plateau" else r_lower(x[k])
        assert abs(r_sma[k] - line) <= 1e-8, (k, e["name"], r_sma[k], line)
    # slopes: between two samples with no event in between, the branch and anchor are fixed
    same = (np.diff(n_ev) == 0) & (s[1:] == 1) & (s[:-1] == 1)
    slope = np.where(branch[1:] == 0, K1, K2)
    resid = np.diff(r_sma) - slope * np.diff(x)
    assert np.all(np.abs(resid[same]) <= 1e-9), np.max(np.abs(resid[same]))
    assert np.sum(same & (branch[1:] == 0) & (np.abs(np.diff(x)) > 1e-4)) > 50
    # non-vacuous: inner loops happened (reloads from the lower plateau, reversals on the upper)
    names = [e["name"] for e in events]
    assert names.count("reload") >= 3 and names.count("reversal") >= 5, names
    assert min(x) > -0.6  # stayed well inside the domain (xbar > 0)
    assert np.max(np.abs(E + W - E_0 - Wx)) <= 1e-8 * E_0


# ---- bad input, memory across FMU state ----------------------------------------------------------

@pytest.mark.parametrize("values,param,rule", [
    ({"k2": 100.0}, "k2", "k2 < k1 = 100.0"),
    ({"k2": 150.0}, "k2", "k2 < k1 = 100.0"),
    ({"k2": 0.0}, "k2", "k2 > 0"),
    ({"x1": -0.1}, "x1", "x1 < x3 = -0.1"),
    ({"x1": -0.05}, "x1", "x1 < x3 = -0.1"),
    ({"x3": 0.0}, "x3", "x3 < 0"),
    ({"x3": 0.1, "x1": -0.2}, "x3", "x3 < 0"),
    ({"c": -0.5}, "c", "c >= 0"),
    ({"z_0": 0.0, "y_0": 0.7, "xbar_0": 0.7}, "xbar_0", "xbar_0 - x_i >= x1"),
])
def test_bad_parameters_are_rejected_with_a_clear_message(values, param, rule):
    assert_parameter_rejected(NAME, values, param, rule)


def test_fmu_state_restores_the_branch_memory():
    """Save on the lower plateau (branch 2, H_l set), run on, restore: memory and run identical."""
    inst = Instance(NAME).init()
    try:
        inst.run_to(0.7, 1e-3)  # lower plateau: 0.651 < t < 0.776
        saved = inst.outputs()
        t_saved = inst.t
        assert saved["branch"] == 2 and saved["H_l"] < X1
        state = inst.fmu.getFMUstate()
        inst.run_to(2.0, 1e-2)
        first = inst.outputs()
        assert first["H_l"] != saved["H_l"] and first["n_events"] > saved["n_events"]
        inst.fmu.setFMUstate(state)
        inst.t = t_saved
        assert inst.outputs() == saved
        inst.run_to(2.0, 1e-2)
        assert inst.outputs() == first
        inst.fmu.freeFMUstate(state)
    finally:
        inst.close()
