"""The importer's tolerance (fmi2SetupExperiment / fmi3EnterInitializationMode ``toleranceDefined``)
sets the FMU's internal solver's ``rel_tol``, unless the user set ``rel_tol`` itself; the
DefaultExperiment's tolerance is the default ``rel_tol`` (docs/using-fmus.md, "The tolerance").

Driven through fmpy's ``simulate_fmu(..., relative_tolerance=...)`` in co-simulation, on both FMI
versions and both backends; the PogoStick's contact times are compared with the closed form
(``pogofmu.references.closed_form``, 40-digit roots)."""
import pytest

from support import fmu_path, reference_events

NAMES = ["PogoStick", "fmi3/PogoStick", "native/PogoStick", "native/fmi3/PogoStick"]
STOP = 10.0


def event_times(name, **kwargs):
    """The times of the events of a 10 s run, read from ``t_last_event`` on a 1e-3 s grid (the
    events are ~0.1 s apart or more, so every one shows)."""
    res, messages = run(name, STOP, output_interval=1e-3, **kwargs)
    assert res["time"][-1] == pytest.approx(STOP) and not [m for m in messages if m[0] >= 3], messages
    return [t for t, n, n0 in zip(res["t_last_event"][1:], res["n_events"][1:], res["n_events"][:-1]) if n != n0]


def run(name, stop, **kwargs):
    """fmpy's run with the log collected, (status, text); its FMI 2.0 logger has five arguments,
    its FMI 3.0 one four."""
    from fmpy import simulate_fmu

    messages = []
    res = simulate_fmu(str(fmu_path(name)), stop_time=stop, debug_logging=True,
                       logger=lambda *a: messages.append((int(a[-3]), a[-1].decode())), **kwargs)
    return res, messages


def error(times):
    ref = [e["time"] for e in reference_events() if e["time"] <= STOP]
    assert len(times) == len(ref), (len(times), len(ref))
    return max(abs(a - b) for a, b in zip(times, ref))


@pytest.mark.parametrize("name", NAMES)
def test_the_importers_tolerance_sets_the_solvers(name):
    loose = error(event_times(name, relative_tolerance=1e-6))
    tight = error(event_times(name, relative_tolerance=1e-10))
    # the error follows the tolerance (README: 2e-7 s at 1e-6, 1e-9 s at 1e-10)
    assert tight < loose / 20, (tight, loose)
    assert tight < 1e-8, tight


@pytest.mark.parametrize("name", NAMES)
def test_an_explicit_rel_tol_wins_over_the_importers_tolerance(name):
    asked = event_times(name, relative_tolerance=1e-10, start_values={"rel_tol": 1e-6})
    assert asked == event_times(name, relative_tolerance=1e-6)  # the same solver run, to the bit
    assert error(asked) > 20 * error(event_times(name, relative_tolerance=1e-10))


@pytest.mark.parametrize("name", NAMES)
def test_the_default_experiments_tolerance_is_the_default_rel_tol(name):
    """An importer that passes the declared tolerance (fmpy does, given none) runs the solver
    as one that passes nothing: the FMU's results do not depend on which importer it is in."""
    from fmpy import read_model_description

    md = read_model_description(str(fmu_path(name)))
    rel_tol = next(v for v in md.modelVariables if v.name == "rel_tol")
    assert float(md.defaultExperiment.tolerance) == float(rel_tol.start)
    assert event_times(name) == event_times(name, relative_tolerance=float(rel_tol.start))


@pytest.mark.parametrize("name", NAMES)
def test_a_tolerance_outside_rel_tols_rule_is_brought_into_it_with_a_warning(name):
    """FMI's tolerance is a hint: one looser than rel_tol's rule allows runs at the loosest rel_tol
    (the same events as a run with that rel_tol set), with a warning naming both; the same text
    from both backends."""
    from pogofmu.runtime.solver.settings import REL_TOL_MAX

    _, messages = run(name, 0.1, relative_tolerance=1e-2)
    assert [text for status, text in messages if "the importer's tolerance" in text and status == 1] == [
        f"PogoStick: the importer's tolerance = 0.01 lies outside the rule of rel_tol, 1e-14 <= rel_tol <= "
        f"{REL_TOL_MAX:g}: the solver takes rel_tol = {REL_TOL_MAX!r}"], messages
    assert event_times(name, relative_tolerance=1e-2) == event_times(name, start_values={"rel_tol": REL_TOL_MAX})


def test_the_c_adapter_clamps_to_the_rule_of_the_settings():
    """pg_instance.c writes rel_tol's bounds as numbers: they are settings.py's."""
    import re

    from pogofmu.runtime.solver.settings import REL_TOL_MAX, REL_TOL_MIN

    from support import ROOT

    text = (ROOT / "fmu_src" / "native" / "adapter" / "pg_instance.c").read_text()
    found = {k: float(v) for k, v in re.findall(r"#define (REL_TOL_M(?:IN|AX)) (\S+)", text)}
    assert found == {"REL_TOL_MIN": REL_TOL_MIN, "REL_TOL_MAX": REL_TOL_MAX}
    assert f"{REL_TOL_MIN:g} <= rel_tol <= {REL_TOL_MAX:g}" in text
