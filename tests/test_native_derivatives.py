"""Directional derivatives of the native FMUs: exact Jacobian-vector products generated
from the Python model on dual numbers (pogofmu.runtime.dual), checked against finite differences
of the FMU's own functions and against closed forms.

* FMI 3.0 model exchange, along each model's default run under fmpy's CVode: at sample points in
  every mode the run passes through, the Jacobian of der(x) and of the outputs with respect to the
  states, column by column, equals fourth-order differences of fmi3GetContinuousStateDerivatives /
  fmi3GetFloat64 to 1e-10 (where the differences at two step sizes agree, i.e. away from a kink);
* the PogoStick in contact: d der(xdot) / d(xbar, xdot) = (-k/m, -c/m), exactly;
* outputs with respect to inputs: HopController's thrust law, FMI 3.0 and FMI 2.0 co-simulation;
* knowns and unknowns that are not (a parameter, an input as unknown, a wrong seed count) are
  refused with Error naming them; the Python-hosted FMUs still declare no directional derivatives.
"""
import ctypes

import pytest

from pogofmu import exporter as build
from support import fmu_path

MODELS = {name: build.slave_class(name).model for name in build.model_names()}
WITH_STATES = sorted(n for n, m in MODELS.items() if m.states)
D = ctypes.c_double


def _dd3(fmu, unknowns, knowns, seed):
    f = fmu.dll.fmi3GetDirectionalDerivative
    f.restype = ctypes.c_int
    f.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_size_t,
                  ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_size_t]
    out = (D * len(unknowns))()
    status = f(fmu.component, (ctypes.c_uint32 * len(unknowns))(*unknowns), len(unknowns),
               (ctypes.c_uint32 * len(knowns))(*knowns), len(knowns), (D * len(seed))(*seed), len(seed),
               out, len(unknowns))
    return status, list(out)


def _dd2(fmu, unknowns, knowns, seed):
    f = fmu.dll.fmi2GetDirectionalDerivative
    f.restype = ctypes.c_int
    f.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_size_t,
                  ctypes.c_void_p, ctypes.c_void_p]
    out = (D * len(unknowns))()
    status = f(fmu.component, (ctypes.c_uint32 * len(unknowns))(*unknowns), len(unknowns),
               (ctypes.c_uint32 * len(knowns))(*knowns), len(knowns), (D * len(seed))(*seed), out)
    return status, list(out)


def _me_instance(name, messages, start=None):
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Model

    path = fmu_path(f"native/fmi3/{name}")
    md = read_model_description(str(path))
    fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="dd")
    fmu.instantiate(loggingOn=True, logMessage=lambda env, st, cat, msg: messages.append((st, msg.decode())))
    by_name = {v.name: v for v in md.modelVariables}
    for key, value in (start or {}).items():
        fmu.setFloat64([by_name[key].valueReference], [value])
    return fmu, md, by_name


def _state_vrs(md, by_name):
    der = [v for v in md.modelVariables if v.name.startswith("der(")]
    return [by_name[d.name[4:-1]].valueReference for d in der], [d.valueReference for d in der]


def _jacobian_check(fmu, md, by_name, where):
    """At the instance's current point: every column of d(der(x), real outputs)/dx against
    fourth-order differences through the FMU (to 1e-10, where no switch lies within the stencil);
    returns how many entries were compared."""
    x_vrs, der_vrs = _state_vrs(md, by_name)
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Float64"]
    nx = len(x_vrs)
    x0 = (D * nx)()
    fmu.getContinuousStates(x0, nx)
    x0 = list(x0)

    def values(x):
        fmu.setContinuousStates((D * nx)(*x), nx)
        der = (D * nx)()
        fmu.getContinuousStateDerivatives(der, nx)
        return list(der) + list(fmu.getFloat64(outs))
    compared = 0

    def five_point(j, h):
        """The fourth-order difference (-f(x+2h) + 8 f(x+h) - 8 f(x-h) + f(x-2h)) / 12h, column j."""
        at = [values(x0[:j] + [x0[j] + k * h] + x0[j + 1:]) for k in (2, 1, -1, -2)]
        return [(-a + 8 * b - 8 * c + d) / (12 * h) for a, b, c, d in zip(*at)]

    def one_sided(j, h):
        """The fourth-order one-sided difference (-25 f0 + 48 f1 - 36 f2 + 16 f3 - 3 f4) / 12h towards
        the sign of h: with the other side's, it tells a kink at the point itself."""
        at = [values(x0[:j] + [x0[j] + k * h] + x0[j + 1:]) for k in range(5)]
        return [(-25 * a + 48 * b - 36 * c + 16 * d - 3 * e) / (12 * h) for a, b, c, d, e in zip(*at)]

    size = max(abs(v) for v in values(x0))  # the rounding of a difference scales with the values
    for j in range(nx):
        values(x0)  # (the differences of the previous column left the instance at a perturbed state)
        status, exact = _dd3(fmu, der_vrs + outs, [x_vrs[j]], [1.0])
        assert status == 0
        h = 1e-3 * max(1.0, abs(x0[j]))
        coarse, fine = five_point(j, h), five_point(j, h / 2)
        right, left = one_sided(j, h / 4), one_sided(j, -h / 4)
        for i, e in enumerate(exact):
            scale = max(1.0, abs(fine[i]), abs(e))
            if abs(coarse[i] - fine[i]) > 1e-8 * scale or abs(right[i] - left[i]) > 1e-6 * scale:
                continue  # a kink or a switch within 2h, or at the point itself: no derivative to compare
            # truncation O(h^4) ~ 1e-12 and rounding ~ 1e-16 |f| / h: the generated derivative to 1e-10
            assert abs(e - fine[i]) <= 1e-10 * max(scale, size), (where, j, i, e, fine[i])
            compared += 1
    fmu.setContinuousStates((D * nx)(*x0), nx)
    return compared


@pytest.mark.parametrize("name", WITH_STATES)
def test_model_exchange_jacobians_equal_finite_differences_along_the_default_run(name):
    from fmpy import read_model_description, simulate_fmu

    path = fmu_path(f"native/fmi3/{name}")
    md = read_model_description(str(path))
    by_name = {v.name: v for v in md.modelVariables}
    stop = float(md.defaultExperiment.stopTime)
    samples = [stop * k / 9 for k in range(1, 9)]
    seen = {"modes": set(), "compared": 0}

    def step_finished(time, recorder):
        if samples and time >= samples[0]:
            samples.pop(0)
            fmu = recorder.fmu
            seen["modes"].add(tuple(fmu.getInt32([v.valueReference for v in md.modelVariables
                                                  if v.causality == "output" and v.type == "Int32"
                                                  and v.name not in ("n_events", "last_event")])))
            seen["compared"] += _jacobian_check(fmu, md, by_name, (name, time))
        return True
    res = simulate_fmu(str(path), fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-8,
                       output_interval=1e-2, step_finished=step_finished)
    assert res["time"][-1] == pytest.approx(stop)
    assert not samples and seen["compared"] > 40 and len(seen["modes"]) >= 2, seen


def test_pogostick_in_contact_has_the_closed_form_jacobian():
    messages = []
    k, c, m = 100.0, 0.5, 1.0
    fmu, md, by_name = _me_instance("PogoStick", messages, {"y_0": 0.95, "xbar_0": 0.95, "z_0": 0.0})
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.updateDiscreteStates()
    fmu.enterContinuousTimeMode()
    assert fmu.getInt32([by_name["s"].valueReference]) == [1]  # contact
    x_vrs, der_vrs = _state_vrs(md, by_name)
    row = by_name["der(xdot)"].valueReference
    status, col_xbar = _dd3(fmu, [row], [by_name["xbar"].valueReference], [1.0])
    status2, col_xdot = _dd3(fmu, [row], [by_name["xdot"].valueReference], [1.0])
    assert status == status2 == 0
    assert col_xbar == [-k / m] and col_xdot == [-c / m]
    # linear in the seed: two knowns at once
    status, both = _dd3(fmu, [row], [by_name["xbar"].valueReference, by_name["xdot"].valueReference], [2.0, -4.0])
    assert status == 0 and both == [2.0 * (-k / m) + (-4.0) * (-c / m)]
    # a state's derivative with respect to itself is 1, to another 0
    status, ident = _dd3(fmu, [by_name["y"].valueReference, by_name["xbar"].valueReference],
                         [by_name["y"].valueReference], [1.0])
    assert status == 0 and ident == [1.0, 0.0]
    fmu.terminate()
    fmu.freeInstance()


def test_controller_outputs_with_respect_to_its_inputs_fmi3_and_fmi2():
    """HopController: d(F_ext, E_est, E_err)/d(y, ydot) against central differences, in FMI 3.0
    model exchange (outputs follow the inputs at once) and FMI 2.0 co-simulation (a step of 0)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    messages = []
    fmu, md, by_name = _me_instance("HopController", messages)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.updateDiscreteStates()
    fmu.enterContinuousTimeMode()
    ins = [by_name[n].valueReference for n in ("y", "ydot")]
    outs = [by_name[n].valueReference for n in ("F_ext", "E_est", "E_err")]
    point = [1.1, 0.4]
    fmu.setFloat64(ins, point)
    for j in range(2):
        status, exact = _dd3(fmu, outs, [ins[j]], [1.0])
        assert status == 0
        h = 1e-6
        fmu.setFloat64([ins[j]], [point[j] + h])
        plus = fmu.getFloat64(outs)
        fmu.setFloat64([ins[j]], [point[j] - h])
        minus = fmu.getFloat64(outs)
        fmu.setFloat64([ins[j]], [point[j]])
        for e, a, b in zip(exact, plus, minus):
            assert abs(e - (a - b) / (2 * h)) <= 1e-6 * max(1.0, abs(e)), (j, exact, plus, minus)
    assert any(abs(e) > 0 for j in range(2) for e in _dd3(fmu, outs, [ins[j]], [1.0])[1])
    fmu.terminate()
    fmu.freeInstance()

    path = fmu_path("native/HopController")
    md2 = read_model_description(str(path))
    vr2 = {v.name: v.valueReference for v in md2.modelVariables}
    cs = FMU2Slave(guid=md2.guid, unzipDirectory=extract(str(path)), modelIdentifier=md2.coSimulation.modelIdentifier,
                   instanceName="dd2")
    from support import fmi2_callbacks

    callbacks = fmi2_callbacks([])
    cs.instantiate(callbacks=callbacks.struct)
    cs.setupExperiment(startTime=0.0)
    cs.enterInitializationMode()
    cs.exitInitializationMode()
    cs.setReal([vr2["y"], vr2["ydot"]], point)
    cs.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.0)
    status, exact2 = _dd2(cs, [vr2["F_ext"], vr2["E_est"], vr2["E_err"]], [vr2["ydot"]], [1.0])
    assert status == 0
    h = 1e-6
    cs.setReal([vr2["ydot"]], [point[1] + h])
    cs.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.0)
    plus = cs.getReal([vr2["F_ext"], vr2["E_est"], vr2["E_err"]])
    cs.setReal([vr2["ydot"]], [point[1] - h])
    cs.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.0)
    minus = cs.getReal([vr2["F_ext"], vr2["E_est"], vr2["E_err"]])
    for e, a, b in zip(exact2, plus, minus):
        assert abs(e - (a - b) / (2 * h)) <= 1e-6 * max(1.0, abs(e))
    cs.terminate()
    cs.freeInstance()


def test_what_is_not_a_known_or_an_unknown_is_refused_by_name():
    messages = []
    fmu, md, by_name = _me_instance("PogoStick", messages)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    der = by_name["der(y)"].valueReference
    cases = [([der], [by_name["k"].valueReference], [1.0], "k (value reference"),
             ([by_name["F_ext"].valueReference], [by_name["y"].valueReference], [1.0], "F_ext (value reference"),
             ([der], [99999], [1.0], "value reference 99999 is not a variable of PogoStick")]
    for unknowns, knowns, seed, text in cases:
        status, _ = _dd3(fmu, unknowns, knowns, seed)
        assert status == 3 and text in messages[-1][1] and "fmi3GetDirectionalDerivative refused" in messages[-1][1]
    f = fmu.dll.fmi3GetDirectionalDerivative
    status = f(fmu.component, (ctypes.c_uint32 * 1)(der), 1, (ctypes.c_uint32 * 1)(by_name["y"].valueReference), 1,
               (D * 2)(1.0, 1.0), 2, (D * 1)(), 1)
    assert status == 3 and "nSeed = 2" in messages[-1][1]
    status, ok = _dd3(fmu, [der], [by_name["ydot"].valueReference], [1.0])  # still usable after the errors
    assert status == 0 and ok == [1.0]
    fmu.freeInstance()


@pytest.mark.parametrize("name", sorted(MODELS))
def test_only_the_native_fmus_declare_directional_derivatives(name):
    import xml.etree.ElementTree as ET
    import zipfile

    def flags(path, attribute):
        with zipfile.ZipFile(fmu_path(path)) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
        return [root.find(i).get(attribute) for i in ("ModelExchange", "CoSimulation") if root.find(i) is not None]
    assert flags(f"native/{name}", "providesDirectionalDerivative") == ["true"]
    assert flags(f"native/fmi3/{name}", "providesDirectionalDerivatives") == ["true", "true"]
    assert flags(name, "providesDirectionalDerivative") == ["false"]
    assert flags(f"fmi3/{name}", "providesDirectionalDerivatives") == ["false", "false"]
