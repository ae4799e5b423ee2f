"""ctypes access to the native engine (fmu_src/native/engine/pg_engine.h) built with one model, and
the binding's run of the model's Python functions (the Python-hosted backend) side by side with it,
step by step."""
from __future__ import annotations

import ctypes as C

from native_model import PgModel, arr, same_number
from pogofmu.runtime.solver import SOLVER_PARAMETERS, Simulator
from pogofmu.runtime.model import ModelError


class NativeEngine:
    def __init__(self, path):
        L = self.lib = C.CDLL(str(path))
        L.pg_engine_sizeof.restype = C.c_size_t
        L.pg_engine_message.restype = C.c_char_p
        L.pg_engine_message.argtypes = [C.c_void_p]
        L.pg_engine_init.argtypes = [C.c_void_p, C.c_void_p, C.c_void_p, C.c_void_p, C.c_void_p, C.c_double,
                                     C.c_double]
        L.pg_engine_advance.argtypes = [C.c_void_p, C.c_double]
        L.pg_engine_advance_to_event.argtypes = [C.c_void_p, C.c_double, C.POINTER(C.c_int)]
        L.pg_engine_set_input.argtypes = [C.c_void_p, C.c_void_p]
        L.pg_engine_served.argtypes = [C.c_void_p, C.POINTER(C.c_double), C.c_void_p, C.c_void_p,
                                       C.POINTER(C.c_long)]
        L.pg_engine_last_event.argtypes = [C.c_void_p, C.POINTER(C.c_double), C.POINTER(C.c_int)]
        self.model = PgModel.in_dll(L, "PG_MODEL")
        # the same model without its exact directional derivative: the engine's Jacobian by differences
        self.model_without_jvp = PgModel.from_buffer_copy(self.model)
        self.model_without_jvp.flow_jvp = None
        self.size = L.pg_engine_sizeof()
        L.pg_engine_stats.argtypes = [C.c_void_p, *[C.POINTER(C.c_long)] * 4, C.POINTER(C.c_int)]

    def start(self, model, p, s, u, t0=0.0, t_stop=float("inf"), jvp=True):
        """A new engine: ``(handle, None)`` or ``(None, message)``; ``jvp=False``: the model's
        flow_jvp hidden (the Jacobian by differences, as for a model without one)."""
        buf = C.create_string_buffer(self.size)
        rc = self.lib.pg_engine_init(buf, C.byref(self.model if jvp else self.model_without_jvp), arr([p[par.name] for par in model.parameters]),
                                     arr([s[par.name] for par in SOLVER_PARAMETERS]), arr(u), t0, t_stop)
        return (buf, None) if rc == 0 else (None, self.lib.pg_engine_message(buf).decode())

    def message(self, e):
        return self.lib.pg_engine_message(e).decode()

    def served(self, e):
        t, x, q, n = C.c_double(), (C.c_double * 32)(), (C.c_double * 16)(), C.c_long()
        self.lib.pg_engine_served(e, C.byref(t), x, q, C.byref(n))
        return t.value, list(x[:self.model.nx]), list(q[:self.model.nq]), n.value

    def stats(self, e):
        """(accepted steps, rejected steps, Jacobians, method switches, the method in use)"""
        v, cur = [C.c_long() for _ in range(4)], C.c_int()
        self.lib.pg_engine_stats(e, *(C.byref(x) for x in v), C.byref(cur))
        return (*(x.value for x in v), cur.value)

    def last_event(self, e):
        t, i = C.c_double(), C.c_int()
        return (t.value, i.value) if self.lib.pg_engine_last_event(e, C.byref(t), C.byref(i)) else None


def both_runs(native, model, p, s, steps, inputs=None, t_stop=float("inf"), early=False, outcome=None):
    """Run the binding (the Python model) and the native model side by side over ``steps`` communication points
    (``inputs[k]``: the inputs held from point k on); returns a list of differences (empty: the
    same bits at every point, the same events, the same message if a run stops). ``outcome``, a
    set if given, collects how the run ended: init, input or advance (a message) or ok."""
    diffs = []
    outcome = set() if outcome is None else outcome
    # every method, the stiff ones too: where method 0 (the default) or 1 runs Rodas5P, its Jacobian
    # is the exact one on both sides (the generated flow_jvp in C, the model's flow on dual numbers
    # in the binding), the same operations
    u0 = [float(v.start) for v in model.inputs] if not inputs else [float(x) for x in inputs[0]]
    params = {**p, **s}
    try:
        sim = Simulator(model, params, u=tuple(u0), t_stop=t_stop)
        py_err = None
    except ModelError as exc:
        sim, py_err = None, str(exc)
    e, c_err = native.start(model, p, s, u0, 0.0, t_stop)
    if py_err or c_err:
        if py_err != c_err:
            diffs.append(("init", py_err, c_err))
        outcome.add("init")
        return diffs
    stop = C.c_int()
    for k, tk in enumerate(steps):
        if inputs:
            u = tuple(float(x) for x in inputs[k % len(inputs)])
            try:
                sim.set_input(u)
                py_err = None
            except ModelError as exc:
                py_err = str(exc)
            rc = native.lib.pg_engine_set_input(e, arr(u))
            c_err = native.message(e) if rc else None
            if py_err or c_err:
                if py_err != c_err:
                    diffs.append(("input", tk, py_err, c_err))
                outcome.add("input")
                return diffs
        try:
            if early:  # FMI 3.0 early return: stop at each event, apply its jump, go on
                while sim.advance_to_event(tk):
                    sim.advance(sim.t_out)
            else:
                sim.advance(tk)
            py_err = None
        except ModelError as exc:
            py_err = str(exc)
        if early:
            while True:
                rc = native.lib.pg_engine_advance_to_event(e, tk, C.byref(stop))
                if rc or not stop.value:
                    break
                rc = native.lib.pg_engine_advance(e, native.served(e)[0])
                if rc:
                    break
        else:
            rc = native.lib.pg_engine_advance(e, tk)
        c_err = native.message(e) if rc else None
        if py_err or c_err:
            if py_err != c_err:
                diffs.append(("advance", tk, py_err, c_err))
            outcome.add("advance")
            return diffs
        t, x, q, n = native.served(e)
        if not same_number(t, sim.t_out):
            diffs.append(("t_out", tk, sim.t_out, t))
        bad = [(i, a, b) for i, (a, b) in enumerate(zip(sim.x_out, x)) if not same_number(a, b)]
        qbad = [(kk, a, b) for kk, a, b in zip(sim.q_out, sim.q_out.values(), q) if not same_number(a, b)]
        last = native.last_event(e)
        py_last = None if sim.last_event is None else (sim.last_event.time, sim.last_event.index)
        if bad or qbad or n != sim.n_events or (last != py_last and not (last and py_last and
                                                                        same_number(last[0], py_last[0]))):
            diffs.append(("state", tk, bad[:3], qbad[:3], (sim.n_events, n), (py_last, last)))
            return diffs
    outcome.add("ok")
    return diffs
