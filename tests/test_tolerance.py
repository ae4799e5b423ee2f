"""The importer's tolerance (fmi2SetupExperiment / fmi3EnterInitializationMode ``toleranceDefined``)
sets the FMU's internal solver's ``rel_tol``, unless the user set ``rel_tol`` itself; the
DefaultExperiment's tolerance is the default ``rel_tol`` (docs/using-fmus.md, "The tolerance").

Driven through fmpy's ``simulate_fmu(..., relative_tolerance=...)`` in co-simulation, on both FMI
versions and both backends; the PogoStick's contact times are compared with the closed form
(``pogofmu.references.closed_form``, 40-digit roots)."""
import pytest

from support import fmu_path, reference_events, simulate

NAMES = ["PogoStick", "fmi3/PogoStick", "native/PogoStick", "native/fmi3/PogoStick"]
STOP = 10.0


def event_times(name, **kwargs):
    """The times of the events of a 10 s run, read from ``t_last_event`` on a 1e-3 s grid (the
    events are ~0.1 s apart or more, so every one shows)."""
    run = simulate(name, stop_time=STOP, output_interval=1e-3, **kwargs)
    assert not run.errors, run.errors
    res = run.res
    return [t for t, n, n0 in zip(res["t_last_event"][1:], res["n_events"][1:], res["n_events"][:-1]) if n != n0]


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
