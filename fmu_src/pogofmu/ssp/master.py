"""Running a system: instantiate and initialize its FMUs in connection order, then step them with
the chosen master algorithm, recording every connector."""
from __future__ import annotations

import math
import shutil
import sys
import tempfile
import time as _time
from pathlib import Path
from typing import Optional

from .package import Component, SSPError, read_ssd, unpack
from .record import Result
from .validate import _fmu_unit, validate

ALGORITHMS = ("gauss-seidel", "jacobi")

from pogofmu.runtime.status import status_name as _label  # noqa: E402


class _Instance:
    """One FMU of the system, instantiated with fmpy, with its log kept."""

    def __init__(self, comp: Component, workdir: Path, echo):
        from fmpy import extract
        from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, \
            fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE
        from fmpy import calloc, free

        self.comp = comp
        self.messages = []
        self.dead = False
        md = comp.model_description
        self.dir = extract(str(comp.model_description_path), unzipdir=str(workdir / comp.name))
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=self.dir, modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=comp.name)

        def logger(component, instance, status, category, message):
            text = message.decode(errors="replace") if message else ""
            self.messages.append((int(status), text))
            if status >= 1 and echo:
                print(f"[{_label(status)}] {comp.name}: {text}", file=sys.stderr, flush=True)

        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(logger)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._cb = cb  # keep the callbacks alive
        self.fmu.instantiate(loggingOn=True, callbacks=cb)

    def last_error(self):
        for status, text in reversed(self.messages):
            if status >= 2:
                return text
        return "no message from the FMU"

    def vr(self, name):
        return self.comp.variables[name].valueReference

    def set_value(self, name, value):
        var = self.comp.variables[name]
        if var.type == "Real":
            self.fmu.setReal([var.valueReference], [float(value)])
        elif var.type in ("Integer", "Enumeration"):
            self.fmu.setInteger([var.valueReference], [int(value)])
        elif var.type == "Boolean":
            self.fmu.setBoolean([var.valueReference], [bool(value)])
        else:
            self.fmu.setString([var.valueReference], [str(value)])

    def close(self):
        if self.dead:  # FMI 2.0: nothing may be called on an instance after fmi2Fatal
            return
        try:
            self.fmu.terminate()
        finally:
            self.fmu.freeInstance()



def simulate(ssp, parameters: Optional[str] = None, stop_time: Optional[float] = None, step: float = 1e-3,
             start_time: Optional[float] = None, algorithm: str = "gauss-seidel", progress: bool = False,
             echo_log: bool = True, sink=None):
    """Run an SSP package; return a :class:`Result` (see the module docstring).

    ``sink(names, types, units, n_rows)``, if given, makes the recorder instead (an object with
    ``add(row)`` and ``close(complete)``, e.g. a :class:`CSVStream`): it is called once the package
    and every number are found valid, before any FMU is loaded, and what it returns is returned.
    """
    # no scipy import: the FMUs do not use scipy (the workaround of README "Known issues" is for
    # scipy-using FMUs) and it would cost the master 50 MB of its 150 MB budget (issue 9 item 10)
    if algorithm not in ALGORITHMS:
        raise SSPError(f"algorithm {algorithm!r} is not one of {ALGORITHMS}")
    for what, value in (("communication step (--step)", step), ("stop time (--stop-time)", stop_time),
                        ("start time", start_time)):
        if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value)):
            raise SSPError(f"{what} = {value!r} must be a finite number")
    if not step > 0:
        raise SSPError(f"communication step (--step) = {step!r} must be > 0")
    work = Path(tempfile.mkdtemp(prefix="pogofmu_ssp_"))
    instances = {}
    res = None
    try:
        root = unpack(Path(ssp), work / "package")
        system = read_ssd(root)
        selected = validate(system, parameters)
        t0 = system.start_time if start_time is None else float(start_time)
        t_end = stop_time if stop_time is not None else system.stop_time
        if t_end is None:
            raise SSPError("no stop time: give one (--stop-time) or set ssd:DefaultExperiment stopTime")
        if not t_end > t0:
            raise SSPError(f"stop time {t_end!r} s must be later than the start time {t0!r} s")
        n_steps = int(round((t_end - t0) / step))
        if n_steps < 1 or not math.isclose(t0 + n_steps * step, t_end, rel_tol=1e-9, abs_tol=1e-12):
            raise SSPError(f"stop time {t_end} - start time {t0} is not a whole number of steps {step}")
        order = system.order()
        for name in order:
            comp = system.components[name]
            comp.model_description_path = root / comp.source
        # incoming connections of every component, in connection order
        incoming = {name: [c for c in system.connections if c.end_element == name] for name in order}
        # record: every connector of every component
        record = [(name, con) for name in order for con in system.components[name].connectors.values()]
        columns = ([f"{n}.{c.name}" for n, c in record], [c.type for _, c in record],
                   [c.unit or _fmu_unit(system.components[n].variables[c.name]) for n, c in record], n_steps + 1)
        res = (sink or Result)(*columns)
        outputs = {name: [c for c in system.components[name].connectors.values() if c.kind != "input"]
                   for name in order}
        value = {}  # (component, connector) -> latest value of an output connector

        def read_outputs(inst):
            comp = inst.comp
            reals = [c.name for c in outputs[comp.name] if c.type == "Real"]
            ints = [c.name for c in outputs[comp.name] if c.type in ("Integer", "Enumeration")]
            if reals:
                for n, v in zip(reals, inst.fmu.getReal([inst.vr(n) for n in reals])):
                    value[(comp.name, n)] = v
            if ints:
                for n, v in zip(ints, inst.fmu.getInteger([inst.vr(n) for n in ints])):
                    value[(comp.name, n)] = v

        inputs_now = {}  # (component, connector) -> value set for the coming step

        def set_inputs(inst):
            reals, rv, ints, iv = [], [], [], []
            for c in incoming[inst.comp.name]:
                v = value[(c.start_element, c.start_connector)]
                inputs_now[(c.end_element, c.end_connector)] = v
                var = inst.comp.variables[c.end_connector]
                if var.type == "Real":
                    reals.append(var.valueReference)
                    rv.append(float(v))
                else:
                    ints.append(var.valueReference)
                    iv.append(int(v))
            if reals:
                inst.fmu.setReal(reals, rv)
            if ints:
                inst.fmu.setInteger(ints, iv)

        def store(t):
            row = [t]
            for name, con in record:
                key = (name, con.name)
                if con.kind == "input":
                    v = inputs_now.get(key)
                    if v is None:
                        v = instances[name].fmu.getReal([instances[name].vr(con.name)])[0] if con.type == "Real" \
                            else instances[name].fmu.getInteger([instances[name].vr(con.name)])[0]
                else:
                    v = value[key]
                row.append(v)
            res.add(row)

        # ---- instantiate and initialize, in order ----
        for name in order:
            comp = system.components[name]
            inst = instances[name] = _Instance(comp, work, echo_log)
            # no stop time for the FMUs (stopTimeDefined = false): the engine clamps its steps at a
            # defined stop time, and an input change within ~1e-14 s of it ends in a 'step size
            # collapsed' fatal error (seen with PogoStick at t = 6 - 1e-14 s; report of issue 5)
            inst.fmu.setupExperiment(startTime=t0)
            inst.fmu.enterInitializationMode()
            ps = selected.get(name)
            try:
                for p in (ps.parameters if ps is not None else []):
                    if p.name in comp.variables:
                        inst.set_value(p.name, p.value)
                if all((c.start_element, c.start_connector) in value for c in incoming[name]):
                    set_inputs(inst)
                inst.fmu.exitInitializationMode()
            except Exception as exc:  # noqa: BLE001 - fmpy raises FMICallException on an error status
                inst.dead = "fatal" in str(exc).lower()
                raise SSPError(f"Component {name}: initialization failed with "
                               f"{ps.source if ps else 'no parameter set'}: {inst.last_error()}") from None
            read_outputs(inst)
        for name in order:  # inputs of earlier components fed by later ones
            set_inputs(instances[name])
        store(t0)

        # ---- fixed-step loop ----
        insts = [instances[n] for n in order]
        marks = {int(round(n_steps * q / 10)) for q in range(1, 11)} if progress else set()
        wall0 = _time.perf_counter()
        for k in range(n_steps):
            t = t0 + k * step
            if algorithm == "jacobi":
                for inst in insts:
                    set_inputs(inst)
            for inst in insts:
                if algorithm == "gauss-seidel":
                    set_inputs(inst)
                try:
                    inst.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=step)
                except Exception as exc:  # noqa: BLE001 - FMICallException: status discard/error/fatal
                    inst.dead = "fatal" in str(exc).lower()
                    raise SSPError(f"Component {inst.comp.name}: fmi2DoStep from t = {t:.10g} s "
                                   f"(step {step:g} s) failed ({exc}): {inst.last_error()}") from None
                if algorithm == "gauss-seidel":
                    read_outputs(inst)
            if algorithm == "jacobi":
                for inst in insts:
                    read_outputs(inst)
            for c in system.connections:  # the values the inputs will get for the next step
                inputs_now[(c.end_element, c.end_connector)] = value[(c.start_element, c.start_connector)]
            store(t0 + (k + 1) * step)
            if k + 1 in marks:
                el = _time.perf_counter() - wall0
                frac = (k + 1) / n_steps
                print(f"{system.name}: {100 * frac:3.0f} %  t = {t0 + (k + 1) * step:.6g} s  "
                      f"({k + 1}/{n_steps} steps, {el:.1f} s elapsed, ~{el / frac - el:.1f} s left)", flush=True)
        res.system = system.name
        res.parameter_set = ", ".join(sorted({ps.name for ps in selected.values() if ps is not None})) or "none"
        res.algorithm, res.step, res.connections = algorithm, step, list(system.connections)
        res.close(complete=True)
        res.last_time = t0 + n_steps * step
        return res
    finally:
        if res is not None:
            res.close(complete=False)  # a no-op once the run is complete
        for inst in instances.values():
            try:
                inst.close()
            except Exception:  # noqa: BLE001 - never mask the real error while cleaning up
                pass
        shutil.rmtree(work, ignore_errors=True)

