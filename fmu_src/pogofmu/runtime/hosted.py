"""The Python-hosted FMUs' model for the C adapter (``fmu_src/native/adapter``): what Python alone
must give it.

The launcher of a Python-hosted FMU is the native FMUs' adapter (the FMI rules, in C) with one
difference: its model comes from Python. At instantiation the launcher's model source
(``fmu_src/native/python/pg_source_py.c``) calls the boot code (``pogofmu_boot.hosted``), which
loads the FMU's code and makes a :class:`HostedFmu`: the adapter's ``PgFmu`` (pg_instance.h) built
here at run time — the variable table of :mod:`.interface` with the roles the native FMUs' generated
table has (:func:`.interface.variable_rows`), the instantiation token, the build's name, the log
categories and (FMI 3.0) the arrays — around the ``PgModel`` of a :class:`.solver.cengine.Binding`,
whose functions call the model's Python code. The adapter hands the binding the instance's
parameters and settings (:meth:`HostedFmu.bind`) whenever they change.

Standard library only (ctypes): it goes into every FMU with the rest of the runtime.
"""
from __future__ import annotations

import ctypes as C

from .interface import LOG_CATEGORIES, array_table, fmi2_variables, fmi3_variables, variable_rows
from .solver.cengine import Binding


class PgVar(C.Structure):
    """``PgVar`` of pg_instance.h."""
    _fields_ = [("name", C.c_char_p), ("vr", C.c_uint), ("type", C.c_char), ("causality", C.c_char),
                ("role", C.c_char), ("index", C.c_int), ("start", C.c_double)]


class PgFmu(C.Structure):
    """``PgFmu`` of pg_instance.h."""
    _fields_ = [("model", C.c_void_p), ("vars", C.POINTER(PgVar)), ("n_vars", C.c_int), ("token", C.c_char_p),
                ("build", C.c_char_p), ("fmi", C.c_int), ("log_categories", C.POINTER(C.c_char_p)),
                ("n_log_categories", C.c_int), ("arrays", C.POINTER(C.c_uint)), ("n_arrays", C.c_int)]


class _Table:
    """The constant part of a build's PgFmu (for one FMI version), made once per process: its
    strings stay where they are for the process's life (the build's name, by address, is the owner
    of an FMU state: a state moves between instances of the same build)."""

    def __init__(self, model, fmi: int, token: str, build: str):
        self.model = model
        variables = fmi2_variables(model) if fmi == 2 else fmi3_variables(model)
        rows = variable_rows(model, variables)
        self.names = [name.encode() for name, *_ in rows]
        self.vars = (PgVar * max(len(rows), 1))()
        for i, (name, vr, typ, caus, role, index, start) in enumerate(rows):
            self.vars[i] = PgVar(self.names[i], vr, typ.encode(), caus.encode(), role.encode(), index, float(start))
        self.n_vars = len(rows)
        self.token, self.build = token.encode(), build.encode()
        self.categories_raw = [c.encode() for c in LOG_CATEGORIES]
        self.categories = (C.c_char_p * len(self.categories_raw))(*self.categories_raw)
        arrays = array_table(variables) if fmi == 3 else ()
        self.arrays = (C.c_uint * max(len(arrays), 1))(*arrays)
        self.n_arrays = len(arrays) // 2
        self.fmi = fmi


_TABLES = {}


def _table(model, fmi: int, token: str, build: str) -> _Table:
    key = (build, fmi, token)
    t = _TABLES.get(key)
    if t is None or t.model is not model:
        t = _TABLES[key] = _Table(model, fmi, token, build)
    return t


class HostedFmu:
    """One FMU instance's model for the C adapter: ``fmu_address`` (its PgFmu), ``py_address`` (the
    binding's PgbPy, made current by the adapter around its calls), :meth:`bind`."""

    def __init__(self, model, fmi: int, token: str, build: str, instance_name: str = ""):
        self.instance_name = instance_name
        self.table = t = _table(model, int(fmi), token, build)
        self.binding = Binding(model)
        f = self.fmu = PgFmu()
        f.model = C.addressof(self.binding._struct)
        f.vars = C.cast(t.vars, C.POINTER(PgVar))
        f.n_vars = t.n_vars
        # (a c_char_p of bytes points into them: the same buffers for every instance of the build)
        f.token, f.build = t.token, t.build
        f.fmi = t.fmi
        f.log_categories = C.cast(t.categories, C.POINTER(C.c_char_p))
        f.n_log_categories = len(t.categories_raw)
        f.arrays = C.cast(t.arrays, C.POINTER(C.c_uint))
        f.n_arrays = t.n_arrays
        self.fmu_address = C.addressof(f)
        self.py_address = C.addressof(self.binding._py)

    def bind(self, p_addr: int, s_addr: int) -> None:
        """The instance's parameters and settings (addresses of its doubles) for the model's functions."""
        self.binding.bind(p_addr, s_addr)

    def take_switches(self):
        """The solver's messages noted since the last call (the Jacobian gone to differences: a flow
        that does not run on dual numbers), taken: the adapter logs them (logSolver)."""
        texts = list(self.binding.new_switches)
        self.binding.new_switches.clear()
        return texts
