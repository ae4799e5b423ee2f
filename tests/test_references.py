"""The checked-in outputs of the independent references (tests/data/references/<Model>_ref.csv, as
Reference-FMUs keep theirs): the scipy models still give them, and each FMU's default experiment
has their events."""
import pytest

from references import REFERENCE_OUTPUTS, read_reference
from support import simulate


@pytest.mark.parametrize("model", sorted(REFERENCE_OUTPUTS))
def test_the_references_give_their_checked_in_outputs(model):
    events, _ = REFERENCE_OUTPUTS[model]
    now, stored = events(), read_reference(model)
    assert [n for n, _ in now] == [n for n, _ in stored]
    assert max(abs(a - b) for (_, a), (_, b) in zip(now, stored)) < 1e-10


@pytest.mark.parametrize("backend", ["", "native/"])
@pytest.mark.parametrize("model", sorted(REFERENCE_OUTPUTS))
def test_each_default_experiment_has_its_references_events(model, backend):
    """At rel_tol 1e-10 (DOP853) within 1e-7 s of the scipy model at rtol 1e-13."""
    _, stop = REFERENCE_OUTPUTS[model]
    run = simulate(f"{backend}{model}", start_values={"log_events": 1, "rel_tol": 1e-10, "method": 8},
                   stop_time=stop)
    got = [(e["name"], e["time"]) for e in run.events()]
    ref = read_reference(model)
    assert [n for n, _ in got] == [n for n, _ in ref], (got[:5], ref[:5])
    assert max(abs(a - b) for (_, a), (_, b) in zip(got, ref)) < 1e-7
