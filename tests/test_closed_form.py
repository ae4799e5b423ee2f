"""pogofmu.references.closed_form, the reference the engine and the FMUs are held against, checked itself.

Two independent references: the 20-digit table carried in tests/data (computed outside this
project, see its header), and scipy's DOP853 at rtol 1e-13 integrating the basic stick's
equations written out here."""
import csv
import math
from pathlib import Path

import pytest

from pogofmu.references.closed_form import basic_events, events_as_floats

pytestmark = pytest.mark.own_fmus  # (exports its own FMUs, or needs none)

DATA = Path(__file__).resolve().parent / "data" / "pogo_basic_events.csv"


def test_the_closed_form_reproduces_the_carried_20_digit_table():
    import mpmath

    with DATA.open() as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    got = basic_events()
    assert [e["event"] for e in got] == [r["event"] for r in rows] and len(got) == 19
    with mpmath.workdps(40):
        for e, r in zip(got, rows):
            assert abs(e["time"] - mpmath.mpf(r["time_s"])) < 1e-18, (e, r)
            assert abs(e["ydot"] - mpmath.mpf(r["ydot_m_per_s"])) < 1e-18, (e, r)


@pytest.mark.parametrize("params", [{}, {"k": 250.0, "c": 1.2, "y_0": 2.0, "g": 1.62}, {"m": 3.0, "ydot_0": 1.0}])
def test_the_closed_form_agrees_with_a_tight_numerical_solution(params):
    """The stick's equations (flight: ydot' = -g; contact: m ydot' = -k (y - x_i) - c ydot - m g),
    integrated by scipy with terminal events: the same event sequence to ~1e-10 s."""
    from scipy.integrate import solve_ivp

    p = {**dict(m=1.0, k=100.0, c=0.5, x_i=1.0, g=9.81, y_0=1.5, ydot_0=0.0), **params}
    ref = events_as_floats(params, t_end=4.0)
    assert len(ref) >= 4
    t, y, v, got = 0.0, p["y_0"], p["ydot_0"], []
    contact = False
    while t < 4.0:
        def rhs(_, X):
            acc = (-p["k"] * (X[0] - p["x_i"]) - p["c"] * X[1]) / p["m"] - p["g"] if contact else -p["g"]
            return [X[1], acc]

        ev = lambda _, X: X[0] - p["x_i"]  # noqa: E731 (touchdown and liftoff: y = x_i)
        ev.terminal, ev.direction = True, (1 if contact else -1)
        sol = solve_ivp(rhs, (t, 4.0), [y, v], method="DOP853", rtol=1e-13, atol=1e-15, events=ev)
        if not sol.t_events[0].size:
            break
        t = float(sol.t_events[0][0])
        y, v = float(sol.y_events[0][0][0]), float(sol.y_events[0][0][1])
        got.append(("liftoff" if contact else "touchdown", t, v))
        contact = not contact
    assert [g[0] for g in got] == [e["name"] for e in ref]
    for (name, t_num, v_num), e in zip(got, ref):
        assert abs(t_num - e["time"]) < 1e-9, (name, t_num, e)
        assert abs(v_num - e["ydot"]) < 1e-8 * max(1.0, abs(v_num)), (name, v_num, e)


def test_the_first_touchdown_is_the_free_fall_time():
    e = events_as_floats()[0]
    assert e["name"] == "touchdown" and e["time"] == pytest.approx(math.sqrt(2 * 0.5 / 9.81), rel=1e-15)


def test_bad_starts_are_refused():
    with pytest.raises(ValueError, match="must exceed x_i"):
        basic_events({"y_0": 0.5})
    with pytest.raises(ValueError, match="underdamped"):
        basic_events({"c": 30.0})
