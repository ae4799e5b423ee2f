"""The code generator's tracer follows ``pogofmu.runtime.fmath`` through the values' own tables:
nothing of the module is replaced while a model is traced, and numbers keep the standard
library's functions (a host that runs a Python-hosted model while it exports another one)."""
import math
import threading

import pytest

from pogofmu.runtime.dual import Dual
from pogofmu.codegen.trace import TraceError, explore, symbol
from pogofmu.runtime import fmath

pytestmark = pytest.mark.own_fmus  # (exports its own FMUs, or needs none)

ORIGINAL = {name: getattr(fmath, name) for name in fmath.__all__}


def test_fmath_is_not_replaced_while_a_model_is_traced_and_numbers_meanwhile_get_math():
    seen = {}

    def on_another_thread():
        seen["same"] = all(getattr(fmath, n) is fn for n, fn in ORIGINAL.items())
        seen["value"] = fmath.sqrt(2.0)

    def traced():
        x = symbol("x", 0)
        th = threading.Thread(target=on_another_thread)
        th.start()
        th.join()
        return fmath.sqrt(x) + fmath.atan2(x, 2.0) + fmath.exp(fmath.sin(x))

    paths = explore(traced, "test")
    assert seen == {"same": True, "value": math.sqrt(2.0)}
    assert type(seen["value"]) is float
    ops = {n.op for p in paths for n in p.nodes}
    assert {"sqrt", "atan2", "exp", "sin"} <= ops


def test_a_dual_number_outside_tracing_gets_its_derivative_from_fmath():
    d = fmath.sqrt(Dual(4.0, 1.0))
    assert (d.v, d.d) == (2.0, 0.25)
    a = fmath.atan2(Dual(1.0, 1.0), 1.0)  # d/dy atan2(y, 1) = 1 / (1 + y^2)
    assert (a.v, a.d) == (math.atan2(1.0, 1.0), 0.5)
    h = fmath.hypot(3.0, Dual(4.0, 1.0))  # d/db hypot = b / hypot
    assert (h.v, h.d) == (5.0, 0.8)
    assert fmath.isfinite(Dual(1.0, 0.0)) and not fmath.isfinite(Dual(math.inf, 0.0))


def test_numbers_keep_the_standard_librarys_errors():
    with pytest.raises(ValueError, match="math domain error"):
        fmath.sqrt(-1.0)
    with pytest.raises(TypeError):
        fmath.log("1")
    assert fmath.isfinite(1) and not fmath.isfinite("1") and not fmath.is_number(None)


def test_the_standard_librarys_function_on_a_traced_value_names_the_rewrite():
    def traced():
        return math.sqrt(symbol("x", 0))

    with pytest.raises(TraceError, match=r"math\.sqrt\(\.\.\.\) of a traced value.*Rewrite: fmath\.sqrt\(\.\.\.\)"):
        explore(traced, "test")
