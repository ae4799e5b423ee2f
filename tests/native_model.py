"""ctypes access to a generated model's C functions (``PG_MODEL`` of fmu_src/native/engine/pg_model.h),
for tests that compare them with the Python model they were generated from."""
from __future__ import annotations

import ctypes as C
import math

from pogofmu.runtime.solver.cengine import PG_ARITH, PG_OK, PG_RAISE, PgMsg, layouts  # noqa: F401 (pg_model.h)

D = C.POINTER(C.c_double)


MSG = C.POINTER(PgMsg)
FN = {
    "check_settings": C.CFUNCTYPE(C.c_int, D, MSG),
    "check": C.CFUNCTYPE(C.c_int, D, MSG),
    "initial": C.CFUNCTYPE(C.c_int, D, D, D, MSG),
    "flow": C.CFUNCTYPE(C.c_int, C.c_double, D, D, D, D, D, MSG),
    "guard": C.CFUNCTYPE(C.c_int, C.c_int, C.c_double, D, D, D, D, D, MSG),
    "active": C.CFUNCTYPE(C.c_int, C.c_int, D, C.POINTER(C.c_int), MSG),
    "jump": C.CFUNCTYPE(C.c_int, C.c_int, C.c_double, D, D, D, D, D, D, MSG),
    "outputs": C.CFUNCTYPE(C.c_int, C.c_double, D, D, D, D, D, MSG),
    "domain": C.CFUNCTYPE(C.c_int, C.c_double, D, D, D, D, D, MSG),
    "time_scales": C.CFUNCTYPE(C.c_int, D, C.c_void_p, C.POINTER(C.c_int), MSG),  # PgScale *out
    "error_scales": C.CFUNCTYPE(C.c_int, D, C.c_void_p, C.POINTER(C.c_int), MSG),
}
STRS = C.POINTER(C.c_char_p)


class PgModel(C.Structure):
    _fields_ = [("name", C.c_char_p), *((n, C.c_int) for n in ("nx", "nq", "nu", "np", "ns", "ny", "ne")),
                ("state_names", STRS), ("q_names", STRS), ("q_kinds", C.c_char_p), ("input_names", STRS),
                ("parameter_names", STRS), ("parameter_kinds", C.c_char_p), ("output_names", STRS),
                ("event_names", STRS), ("event_direction", C.POINTER(C.c_byte)),
                ("has_time_scales", C.c_int), ("has_error_scales", C.c_int),
                *((n, FN[n]) for n in ("check_settings", "check", "initial", "flow", "guard", "active", "jump",
                                       "outputs", "domain", "time_scales", "error_scales")),
                ("flow_jvp", C.c_void_p), ("outputs_jvp", C.c_void_p),
                ("nte", C.c_int), ("time_event_names", STRS), ("time_event", C.c_void_p), ("time_jump", C.c_void_p)]


def arr(values, n=None):
    n = len(values) if n is None else n
    a = (C.c_double * max(n, 1))()
    for i, v in enumerate(values):
        a[i] = float(v)
    return a


class NativeModel:
    """The generated functions of one model, called with Python lists; each returns
    ``("ok", value)``, ``("raise", message)`` or ``("arith", kind, detail)``."""

    def __init__(self, path):
        self.lib = C.CDLL(str(path))
        self.m = PgModel.in_dll(self.lib, "PG_MODEL")

    def _end(self, rc, msg, value):
        if rc == PG_OK:
            return ("ok", value())
        if rc == PG_RAISE:
            return ("raise", msg.text.decode())
        return ("arith", msg.arith, msg.text.decode())

    def check_settings(self, s):
        msg = PgMsg()
        return self._end(self.m.check_settings(arr(s), C.byref(msg)), msg, lambda: None)

    def check(self, p):
        msg = PgMsg()
        return self._end(self.m.check(arr(p), C.byref(msg)), msg, lambda: None)

    def initial(self, p):
        msg, x, q = PgMsg(), (C.c_double * max(self.m.nx, 1))(), (C.c_double * max(self.m.nq, 1))()
        rc = self.m.initial(arr(p), x, q, C.byref(msg))
        return self._end(rc, msg, lambda: (list(x[:self.m.nx]), list(q[:self.m.nq])))

    def flow(self, t, x, q, u, p):
        msg, dx = PgMsg(), (C.c_double * max(self.m.nx, 1))()
        rc = self.m.flow(t, arr(x), arr(q), arr(u), arr(p), dx, C.byref(msg))
        return self._end(rc, msg, lambda: list(dx[:self.m.nx]))

    def guard(self, k, x, q, u, p, t=0.0):
        msg, g = PgMsg(), C.c_double()
        rc = self.m.guard(k, t, arr(x), arr(q), arr(u), arr(p), C.byref(g), C.byref(msg))
        return self._end(rc, msg, lambda: g.value)

    def active(self, k, q):
        msg, on = PgMsg(), C.c_int()
        rc = self.m.active(k, arr(q), C.byref(on), C.byref(msg))
        return self._end(rc, msg, lambda: bool(on.value))

    def jump(self, k, x, q, u, p, t=0.0):
        msg, xn, qn = PgMsg(), (C.c_double * max(self.m.nx, 1))(), (C.c_double * max(self.m.nq, 1))()
        rc = self.m.jump(k, t, arr(x), arr(q), arr(u), arr(p), xn, qn, C.byref(msg))
        return self._end(rc, msg, lambda: (list(xn[:self.m.nx]), list(qn[:self.m.nq])))

    def outputs(self, t, x, q, u, p):
        msg, y = PgMsg(), (C.c_double * max(self.m.ny, 1))()
        rc = self.m.outputs(t, arr(x), arr(q), arr(u), arr(p), y, C.byref(msg))
        return self._end(rc, msg, lambda: list(y[:self.m.ny]))

    def domain(self, t, x, q, u, p, s):
        msg = PgMsg()
        rc = self.m.domain(t, arr(x), arr(q), arr(u), arr(p), arr(s), C.byref(msg))
        return ("ok", None) if rc == PG_OK else self._end(rc, msg, lambda: None)

    def scales(self, which, p):
        lay = layouts()
        msg, out, n = PgMsg(), (lay.scale * lay.max_scales)(), C.c_int()
        rc = getattr(self.m, which)(arr(p), C.addressof(out), C.byref(n), C.byref(msg))

        def value():
            return [(out[k].label.decode(), tuple(out[k].names[j].decode() for j in range(out[k].n_names)),
                     out[k].value) for k in range(n.value)]
        return self._end(rc, msg, value)


ARITH_KIND = {ZeroDivisionError: 1, OverflowError: 2}


def python_result(fn):
    """What a Python call gives, in the form of NativeModel's results."""
    from pogofmu.runtime.model import ModelError

    try:
        return ("ok", fn())
    except ModelError as exc:
        return ("raise", str(exc))
    except (ArithmeticError, ValueError) as exc:
        detail = exc.args[-1] if exc.args and isinstance(exc.args[-1], str) else str(exc)
        return ("arith", ARITH_KIND.get(type(exc), 3), detail)


def same_number(a, b) -> bool:
    """Equal to the bit (NaN equals NaN; 0.0 and -0.0 differ)."""
    a, b = float(a), float(b)
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)
