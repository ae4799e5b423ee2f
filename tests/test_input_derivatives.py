"""FMI 2.0 input interpolation (``canInterpolateInputs``, ``fmi2SetRealInputDerivatives`` of order
1) on one FMU, both backends: the mirror actuator (examples/segmented_mirror/) made linear — the
mem-spring without memory (``beta = 0``), no gust, stops out of reach — is a damped oscillator
``m z'' + c z' + (k + k_m) z = F``, whose answer to a ramp ``F = F0 + dF t`` is written below in
closed form. The FMU is given the ramp as a value and a slope at a communication point, and must
meet the closed form to the solver's tolerance; held at ``F0`` it is far off (so the test can
fail). The refusals are one-line FMI errors naming the variable, the value and the rule; an FMU
state carries the slope."""
from __future__ import annotations

import ctypes
import functools
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from pogofmu.fmpy_raw import raw_call
from support import Instance, fmu_path

BACKENDS = {"python": "examples/MirrorActuator", "native": "examples/native/MirrorActuator"}
P = dict(m=83.0, k=1.2e4, c=50.0, k_m=2.0e3, beta=0.0, A_w=0.0, z_s=1.0, rel_tol=1e-10, abs_tol=1e-14)
F0, DF = 5.0, 40.0  # N, N/s: F reaches 25 N (z ~ 1.8 mm) at 0.5 s
H, N = 1e-3, 500
OK, ERROR = 0, 3


def closed_form(t, F0=F0, dF=DF, p=P):
    """z(t), z'(t) of m z'' + c z' + K z = F0 + dF t from rest at z = 0 (K = k + k_m)."""
    m, c, K = p["m"], p["c"], p["k"] + p["k_m"]
    a = c / (2 * m)
    wd = math.sqrt(K / m - a * a)
    A = -(F0 / K - c * dF / K ** 2)
    B = (a * A - dF / K) / wd
    t = np.asarray(t, dtype=float)
    e, co, si = np.exp(-a * t), np.cos(wd * t), np.sin(wd * t)
    z = (F0 + dF * t) / K - c * dF / K ** 2 + e * (A * co + B * si)
    zd = dF / K + e * ((-a * A + wd * B) * co + (-a * B - wd * A) * si)
    return z, zd


def set_slopes(inst, names, values, orders=None):
    """fmi2SetRealInputDerivatives called bare: its status."""
    n = len(names)
    vrs = (ctypes.c_uint32 * n)(*(inst.vars[x].valueReference if x in inst.vars else x for x in names))
    ords = (ctypes.c_int32 * n)(*(orders or [1] * n))
    vals = (ctypes.c_double * n)(*values)
    return raw_call(inst.fmu, "fmi2SetRealInputDerivatives", vrs, n, ords, vals)


def new(backend, **params):
    return Instance(BACKENDS[backend]).init(**{**P, **params})


@functools.lru_cache(maxsize=None)
def ramp_run(backend, drive):
    """z and z' on the grid k H for the drives: "once" (F0 and the slope set at t = 0, never again),
    "every" (F and the slope set at every communication point, as a master does), "held" (F0 held),
    "zero" (F and a zero slope set at every point), "plain" (F set at every point, no slope call)."""
    inst = new(backend)
    zs, zds = [inst.get("z")], [inst.get("zdot")]
    try:
        for k in range(N):
            t = k * H
            if drive == "once" and k == 0 or drive == "every":
                inst.set(F=F0 + DF * t)
                assert set_slopes(inst, ["F"], [DF]) == OK, inst.messages[-1:]
            elif drive == "held" and k == 0:
                inst.set(F=F0)
            elif drive in ("zero", "plain"):
                inst.set(F=F0 + DF * t)
                if drive == "zero":
                    assert set_slopes(inst, ["F"], [0.0]) == OK
            inst.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=H)
            zs.append(inst.get("z"))
            zds.append(inst.get("zdot"))
    finally:
        inst.close()
    return np.array(zs), np.array(zds)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("drive", ["once", "every"])
def test_a_ramp_input_meets_the_closed_form(backend, drive):
    """The ramp given as value and slope: z within 1e-12 m (of ~1.8e-3 m), z' within 1e-10 m/s;
    measured ~1e-15 m. Held at F0 the same run is off by more than 1e-5 m."""
    z, zd = ramp_run(backend, drive)
    zr, zdr = closed_form(np.arange(N + 1) * H)
    assert np.max(np.abs(z - zr)) < 1e-12
    assert np.max(np.abs(zd - zdr)) < 1e-10
    held, _ = ramp_run(backend, "held")
    assert np.max(np.abs(held - zr)) > 1e-5


@pytest.mark.parametrize("drive", ["once", "every", "held"])
def test_both_backends_give_the_same_bits(drive):
    for a, b in zip(ramp_run("python", drive), ramp_run("native", drive)):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_zero_slope_is_a_held_input_to_the_bit(backend):
    for a, b in zip(ramp_run(backend, "zero"), ramp_run(backend, "plain")):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("backend", BACKENDS)
def test_an_event_under_a_linear_input_is_located_exactly(backend):
    """The ramp pushes the actuator onto its upper stop at z_s = 1.5 mm; the contact time is the
    closed form's first root of z(t) = z_s (brentq to 1e-15 s): the FMU's t_last_event within
    1e-9 s (measured ~1e-13 s). The input is set once, at t = 0."""
    z_s = 1.5e-3
    inst = new(backend, z_s=z_s)
    try:
        inst.set(F=F0)
        assert set_slopes(inst, ["F"], [DF]) == OK
        for k in range(N):
            inst.fmu.doStep(currentCommunicationPoint=k * H, communicationStepSize=H)
            if inst.get("n_events"):
                break
        t_event = inst.get("t_last_event")
    finally:
        inst.close()
    grid = np.arange(N + 1) * H
    zr, _ = closed_form(grid)
    k = int(np.argmax(zr > z_s))
    assert k > 0
    t_ref = brentq(lambda t: float(closed_form(t)[0]) - z_s, grid[k - 1], grid[k], xtol=1e-15)
    assert abs(t_event - t_ref) < 1e-9, (t_event, t_ref)


def _refusal(inst, names, values, orders=None):
    before = len(inst.messages)
    status = set_slopes(inst, names, values, orders)
    text = [m[2] for m in inst.messages[before:] if m[0] >= ERROR]
    return status, text


@functools.lru_cache(maxsize=None)
def refusals(backend):
    """Every refusal's status and messages, then whether the instance still steps."""
    inst = new(backend)
    out = {}
    try:
        out["order 2"] = _refusal(inst, ["F"], [1.0], [2])
        out["order 0"] = _refusal(inst, ["F"], [1.0], [0])
        out["parameter"] = _refusal(inst, ["k"], [1.0])
        out["output"] = _refusal(inst, ["z"], [1.0])
        out["nan"] = _refusal(inst, ["F"], [math.nan])
        out["unknown"] = _refusal(inst, [99999], [1.0])
        out["atomic"] = _refusal(inst, ["F", "k"], [7.0, 1.0])  # the first is not set either
        inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=H)
        out["steps on"] = inst.get("z")
        inst.fmu.terminate()
        out["terminated"] = _refusal(inst, ["F"], [1.0])
    finally:
        inst.fmu.freeInstance()
    return out


@pytest.mark.parametrize("backend", BACKENDS)
def test_bad_calls_are_one_line_errors_naming_variable_value_and_rule(backend):
    r = refusals(backend)
    expect = {
        "order 2": "fmi2SetRealInputDerivatives refused: order = 2 for input F violates the rule: order = 1",
        "order 0": "order = 0 for input F violates the rule: order = 1",
        "parameter": "fmi2SetRealInputDerivatives refused: variable k is a parameter, not an input",
        "output": "fmi2SetRealInputDerivatives refused: variable z is an output, not an input",
        "nan": "the derivative of input F = nan violates the rule: it must be a finite number",
        "unknown": "value reference 99999 is not a variable of MirrorActuator",
        "atomic": "variable k is a parameter",
        "terminated": "fmi2SetRealInputDerivatives refused: not allowed in",
    }
    for case, phrase in expect.items():
        status, text = r[case]
        assert status == ERROR, (case, status)
        assert len(text) == 1 and "\n" not in text[0] and phrase in text[0], (case, text)
    assert r["steps on"] == 0.0  # F = 0 held: the refused slopes were not taken (at rest)


def test_the_refusals_read_the_same_in_both_backends():
    py, nat = refusals("python"), refusals("native")
    for case in py:
        assert py[case] == nat[case], case


@pytest.mark.parametrize("backend", BACKENDS)
def test_an_fmu_state_carries_the_slope(backend):
    """A state taken with a slope set, restored after the slope was cleared (fmi2SetReal of the
    input), and the same state serialized and read back: the steps after each are those of the
    first run to the bit, and not those of the held input."""
    inst = new(backend)
    try:
        inst.set(F=F0)
        assert set_slopes(inst, ["F"], [DF]) == OK
        state = inst.fmu.getFMUstate()
        blob = inst.fmu.serializeFMUstate(state)

        def ten_steps(t0):
            for k in range(10):
                inst.fmu.doStep(currentCommunicationPoint=t0 + k * H, communicationStepSize=H)
            return inst.get("z"), inst.get("zdot")
        first = ten_steps(0.0)
        inst.set(F=F0)  # the slope cleared (a held input from here)
        inst.fmu.setFMUstate(state)
        again = ten_steps(0.0)
        inst.set(F=F0)
        inst.fmu.setFMUstate(inst.fmu.deSerializeFMUstate(blob))
        restored = ten_steps(0.0)
        inst.fmu.freeFMUstate(state)
    finally:
        inst.close()
    assert again == first and restored == first
    zr, zdr = closed_form(10 * H)
    assert abs(first[0] - zr) < 1e-12
    inst2 = new(backend)
    try:  # the held input over the same ten steps: another piston
        inst2.set(F=F0)
        for k in range(10):
            inst2.fmu.doStep(currentCommunicationPoint=k * H, communicationStepSize=H)
        assert inst2.get("z") != first[0]
    finally:
        inst2.close()


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_state_taken_along_the_line_goes_on_along_it(backend):
    """The line set once at t = 0 ("once"), a state taken at t = 0.1 s, mid-line: restored in the same
    instance after 50 more steps, and serialized into a new one, the steps after it are the straight
    run's to the bit, on the closed form. Until 2026-12-07 the restore re-anchored the line at the
    restored point, F(t) = F0 + dF (t - 0.1), with status OK (a user's audit). And a state taken between
    a new value-and-slope call at 0.1 s and the step keeps that call pending: restored, the steps are
    those of the run that made it."""
    z_once, _ = ramp_run(backend, "once")
    k0, k1 = 100, 150

    def steps(inst, a, b):
        out = []
        for k in range(a, b):
            inst.fmu.doStep(currentCommunicationPoint=k * H, communicationStepSize=H)
            out.append(inst.get("z"))
        return out
    inst = new(backend)
    try:
        inst.set(F=F0)
        assert set_slopes(inst, ["F"], [DF]) == OK
        steps(inst, 0, k0)
        state = inst.fmu.getFMUstate()
        blob = inst.fmu.serializeFMUstate(state)
        steps(inst, k0, k1)
        inst.fmu.setFMUstate(state)
        again = steps(inst, k0, k1)
        inst.fmu.freeFMUstate(state)
    finally:
        inst.close()
    other = new(backend)
    try:
        other.fmu.setFMUstate(other.fmu.deSerializeFMUstate(blob))
        moved = steps(other, k0, k1)
    finally:
        other.close()
    straight = list(z_once[k0 + 1:k1 + 1])
    assert again == straight and moved == straight
    zr, _ = closed_form(k1 * H)
    assert abs(again[-1] - zr) < 1e-12 * max(1.0, abs(zr)) + 1e-13

    # a new line set at 0.1 s (value and slope), the state taken before the step that takes it
    F1, DF1 = F0 + 3.0, -20.0

    def relined(take_state):
        inst = new(backend)
        try:
            inst.set(F=F0)
            assert set_slopes(inst, ["F"], [DF]) == OK
            steps(inst, 0, k0)
            inst.set(F=F1)
            assert set_slopes(inst, ["F"], [DF1]) == OK
            if not take_state:
                return steps(inst, k0, k1)
            state = inst.fmu.getFMUstate()
            steps(inst, k0, k1)
            inst.fmu.setFMUstate(state)
            out = steps(inst, k0, k1)
            inst.fmu.freeFMUstate(state)
            return out
        finally:
            inst.close()
    direct, restored = relined(False), relined(True)
    assert restored == direct
    assert direct != straight  # (the new line is another piston: the comparison can fail)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_model_description_declares_input_interpolation(backend):
    from fmpy import read_model_description

    md = read_model_description(str(fmu_path(BACKENDS[backend])))
    assert md.coSimulation.canInterpolateInputs is True
    assert md.coSimulation.maxOutputDerivativeOrder == 0


def test_the_master_refuses_an_unknown_inputs_mode_by_name():
    from pogofmu.ssp import master
    from pogofmu.ssp.package import SSPError
    from support import DIST

    with pytest.raises(SSPError, match="--inputs 'linear' is not one of hold, interpolate"):
        master.simulate(DIST / "SpaceHopper.ssp", inputs="linear", echo_log=False)
