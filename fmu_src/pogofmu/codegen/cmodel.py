"""The C file of one model, generated from its :class:`~pogofmu.runtime.model.HybridModel`.

Every pure function of the model is traced (:mod:`.trace`) and printed (:mod:`.cprint`) as a C
function of ``fmu_src/native/engine/pg_model.h``'s interface: the solver settings' rules, the
parameter rules, the initial state (the pieces of the engine's
:func:`~pogofmu.runtime.solver.simulator.prepare`), the flow as the engine calls it
(``bind(q, u, p)(t, x)``), each event's guard, activity and jump, the outputs, the domain
conditions (with the engine's slack) and the scales. No equation is written a second time: the C
is what the Python does, operation by operation.

    python -m pogofmu.codegen.cmodel PogoStick > PogoStick_model.c
"""
from __future__ import annotations

import sys
from typing import Dict, List

from pogofmu.memo import once_per_model
from pogofmu.runtime.dual import Dual, value_and_tangent
from pogofmu.runtime.solver import SOLVER_PARAMETERS
from pogofmu.runtime.interface import discrete_layout  # the engine's layout of q: one definition
from pogofmu.runtime.solver.settings import check_solver_parameters, domain_slack
from pogofmu.runtime.model import HybridModel, Params

from .cprint import Printer, c_string, literal, matrix_table, message_lines, result_nodes
from .trace import BOOL, FLOAT, INT, Sym, TraceError, explore, symbol

ARGS = {
    "check_settings": "const double *s, PgMsg *m",
    "check": "const double *p, PgMsg *m",
    "initial": "const double *p, double *x_out, double *q_out, PgMsg *m",
    "flow": "double t, const double *x, const double *q, const double *u, const double *p, double *dx, PgMsg *m",
    "guard": "double t, const double *x, const double *q, const double *u, const double *p, double *g, PgMsg *m",
    "active": "const double *q, int *on, PgMsg *m",
    "jump": "double t, const double *x, const double *q, const double *u, const double *p, double *x_new, "
            "double *q_new, PgMsg *m",
    "time_event": "const double *p, double *at, double *every, PgMsg *m",
    "outputs": "double t, const double *x, const double *q, const double *u, const double *p, double *y, PgMsg *m",
    "domain": "double t, const double *x, const double *q, const double *u, const double *p, const double *s, "
              "PgMsg *m",
    "scales": "const double *p, PgScale *out, int *n, PgMsg *m",
    "flow_jvp": "double t, const double *x, const double *q, const double *u, const double *p, const double *sx, "
                "const double *su, double *df, PgMsg *m",
    "outputs_jvp": "double t, const double *x, const double *q, const double *u, const double *p, const double *sx, "
                   "const double *su, double *dy, PgMsg *m",
}
# the name of a generated model's PgModel, which a native FMU's engine calls by name (sizes_header)
ONE_MODEL = "PG_MODEL"
INPUTS = {"t": "t", "x": "x[{i}]", "q": "q[{i}]", "u": "u[{i}]", "p": "p[{i}]", "s": "s[{i}]",
          "sx": "sx[{i}]", "su": "su[{i}]"}


class Inputs:
    """The traced inputs of one call (made inside each run of a path)."""

    def __init__(self, model: HybridModel, layout):
        self.model, self.layout = model, layout

    def t(self):
        return symbol("t", 0)

    def x(self):
        return [symbol("x", i) for i in range(len(self.model.states))]

    def q(self):
        return {k: symbol("q", j, kind) for j, (k, kind) in enumerate(self.layout)}

    def u(self):
        return tuple(symbol("u", i) for i in range(len(self.model.inputs)))

    def p(self):
        return Params({par.name: symbol("p", i, INT if par.integer else FLOAT)
                       for i, par in enumerate(self.model.parameters)})

    def s(self):
        return Params({par.name: symbol("s", i, INT if par.integer else FLOAT)
                       for i, par in enumerate(SOLVER_PARAMETERS)})

    # seeded: the states and the inputs as dual numbers, their tangents the seeds sx, su
    def x_seeded(self):
        return [Dual(symbol("x", i), symbol("sx", i)) for i in range(len(self.model.states))]

    def u_seeded(self):
        return tuple(Dual(symbol("u", i), symbol("su", i)) for i in range(len(self.model.inputs)))


def _raise_lines(path, ref):
    _, cls, text = path.result
    return ["pg_msg_clear(m);", *message_lines(text, ref), "return PG_RAISE;"]


def _number(v) -> bool:
    return isinstance(v, (Sym, bool, int, float))


class ModelWriter:
    def __init__(self, model: HybridModel):
        self.model = model
        self.layout = discrete_layout(model)
        self.inp = Inputs(model, self.layout)
        self.functions: List[str] = []
        self.matrices: Dict[object, str] = {}  # each constant matrix of fmath.matvec -> its C table, once per file

    # ---- one traced function ----
    def function(self, name, args, fn, leaf, what):
        paths = explore(fn, f"{self.model.name}: {what}")

        def roots(path):
            return result_nodes(path.result[1] if path.result[0] == "return" else path.result[2])

        def any_leaf(path, ref):
            if path.result[0] == "raise":
                return _raise_lines(path, ref)
            return leaf(path.result[1], ref)
        body = Printer(paths, INPUTS, any_leaf, roots, self._matrix_name).body()
        unused = [a.split()[-1].lstrip("*") for a in args.split(", ")]
        self.functions.append("\n".join(
            [f"static int {name}({args})", "{", *[f"    (void){u};" for u in unused], *body, "}", ""]))
        return len(paths)

    def _matrix_name(self, M) -> str:
        """The C table of a constant matrix: the same matrix (by value) in several functions is one."""
        name = self.matrices.get(M)
        if name is None:
            name = self.matrices[M] = f"pg_matrix_{len(self.matrices)}"
        return name

    # ---- leaves ----
    def _vector(self, target, n, what):
        def leaf(value, ref):
            if not (isinstance(value, (list, tuple)) and len(value) == n and all(map(_number, value))):
                raise TraceError(f"{self.model.name}: {what} returned {value!r}, not {n} numbers")
            return [f"{target}[{i}] = {ref(v)};" for i, v in enumerate(value)] + ["return PG_OK;"]
        return leaf

    def _q_lines(self, q, target, what):
        keys = [k for k, _ in self.layout]
        if not isinstance(q, dict) or list(q) != keys and set(q) != set(keys):
            raise TraceError(f"{self.model.name}: {what} returned a discrete state with keys {list(q)}, not {keys}")
        return q, keys

    def _state_leaf(self, xname, qname, what):
        nx = len(self.model.states)

        def leaf(value, ref):
            x, q = value
            q, keys = self._q_lines(q, qname, what)
            if len(x) != nx:
                raise TraceError(f"{self.model.name}: {what} returned {len(x)} states, not {nx}")
            return ([f"{xname}[{i}] = {ref(v)};" for i, v in enumerate(x)]
                    + [f"{qname}[{j}] = {ref(q[k])};" for j, k in enumerate(keys)] + ["return PG_OK;"])
        return leaf

    def _scales_leaf(self, value, ref):
        lines = []
        for k, item in enumerate(value):
            label, names, v = item
            if len(names) > 6:
                raise TraceError(f"{self.model.name}: a scale names more than 6 parameters: {names}")
            lines.append(f"out[{k}].label = {c_string(label)};")
            for j, nm in enumerate(names):
                lines.append(f"out[{k}].names[{j}] = {c_string(nm)};")
            lines += [f"out[{k}].n_names = {len(names)};", f"out[{k}].value = {ref(v)};"]
        return lines + [f"*n = {len(value)};", "return PG_OK;"]

    # ---- the whole file ----
    def write(self) -> str:
        model, inp = self.model, self.inp
        nx = len(model.states)
        counts: Dict[str, int] = {}
        # the start of a run in the pieces of the engine's prepare(), traced one by one (the engine
        # calls them in its order); traced as one, the branches of each would multiply
        counts["check_settings"] = self.function(
            "pg_check_settings", ARGS["check_settings"],
            lambda: check_solver_parameters(inp.s(), has_states=bool(model.states)),
            lambda v, ref: ["return PG_OK;"], "the solver's settings")
        counts["check"] = self.function("pg_check", ARGS["check"], lambda: model.check_parameters(inp.p()),
                                        lambda v, ref: ["return PG_OK;"], "the parameter rules")
        counts["initial"] = self.function(
            "pg_initial", ARGS["initial"], lambda: model.initial(inp.p()),
            self._state_leaf("x_out", "q_out", "initial"), "the initial state")

        def flow():
            t, x, q, u, p = inp.t(), inp.x(), inp.q(), inp.u(), inp.p()
            if model.bind is not None:
                return model.bind(q, u, p)(t, x)
            return model.flow(t, x, q, u, p)
        counts["flow"] = self.function("pg_flow", ARGS["flow"], flow, self._vector("dx", nx, "the flow"), "flow")
        for k, ev in enumerate(model.events):
            counts[f"guard {ev.name}"] = self.function(
                f"pg_guard_{k}", ARGS["guard"],
                lambda ev=ev: ev.guard_t(inp.t(), inp.x(), inp.q(), inp.u(), inp.p()),
                lambda v, ref: [f"*g = {ref(v)};", "return PG_OK;"], f"guard of {ev.name}")
            counts[f"active {ev.name}"] = self.function(
                f"pg_active_{k}", ARGS["active"], lambda ev=ev: ev.active(inp.q()),
                lambda v, ref: [f"*on = ({ref(v)}) ? 1 : 0;", "return PG_OK;"], f"activity of {ev.name}")
            counts[f"jump {ev.name}"] = self.function(
                f"pg_jump_{k}", ARGS["jump"],
                lambda ev=ev: ev.jump_t(inp.t(), inp.x(), inp.q(), inp.u(), inp.p()),
                self._state_leaf("x_new", "q_new", f"jump of {ev.name}"), f"jump of {ev.name}")
        for k, ev in enumerate(model.time_events):
            counts[f"time event {ev.name}"] = self.function(
                f"pg_time_event_{k}", ARGS["time_event"], lambda ev=ev: (ev.at(inp.p()), ev.period(inp.p())),
                lambda v, ref: [f"*at = {ref(v[0])};", f"*every = {ref(v[1])};", "return PG_OK;"],
                f"instants of {ev.name}")
            counts[f"time jump {ev.name}"] = self.function(
                f"pg_time_jump_{k}", ARGS["jump"],
                lambda ev=ev: ev.jump_t(inp.t(), inp.x(), inp.q(), inp.u(), inp.p()),
                self._state_leaf("x_new", "q_new", f"jump of {ev.name}"), f"jump of {ev.name}")
        names = [v.name for v in model.outputs]

        def outputs_leaf(value, ref):
            if not isinstance(value, dict) or set(value) != set(names):
                raise TraceError(f"{model.name}: the outputs returned {sorted(value)}, not {sorted(names)}")
            return [f"y[{j}] = {ref(value[n])};" for j, n in enumerate(names)] + ["return PG_OK;"]
        counts["outputs"] = self.function(
            "pg_outputs", ARGS["outputs"],
            lambda: model.output_fn(inp.t(), inp.x(), inp.q(), inp.u(), inp.p()), outputs_leaf, "outputs")

        # directional derivatives: the flow and the outputs on dual numbers (runtime.dual, over traced values)
        def flow_jvp():
            t, x, q, u, p = inp.t(), inp.x_seeded(), inp.q(), inp.u_seeded(), inp.p()
            f = model.bind(q, u, p)(t, x) if model.bind is not None else model.flow(t, x, q, u, p)
            return [value_and_tangent(v)[1] for v in f]
        counts["flow_jvp"] = self.function("pg_flow_jvp", ARGS["flow_jvp"], flow_jvp,
                                           self._vector("df", nx, "the flow's derivative"), "flow derivative")

        def outputs_jvp():
            out = model.output_fn(inp.t(), inp.x_seeded(), inp.q(), inp.u_seeded(), inp.p())
            return {k: value_and_tangent(v)[1] for k, v in out.items()}

        def outputs_jvp_leaf(value, ref):
            if not isinstance(value, dict) or set(value) != set(names):
                raise TraceError(f"{model.name}: the outputs returned {sorted(value)}, not {sorted(names)}")
            return [f"dy[{j}] = {ref(value[n])};" for j, n in enumerate(names)] + ["return PG_OK;"]
        counts["outputs_jvp"] = self.function("pg_outputs_jvp", ARGS["outputs_jvp"], outputs_jvp, outputs_jvp_leaf,
                                              "outputs derivative")

        def domain():
            return model.domain(inp.t(), inp.x(), inp.q(), inp.u(), inp.p(), domain_slack(inp.s()))

        def domain_leaf(value, ref):
            if value is None:
                return ["return PG_OK;"]
            return ["pg_msg_clear(m);", *message_lines(value, ref), "return PG_RAISE;"]
        counts["domain"] = self.function("pg_domain", ARGS["domain"], domain, domain_leaf, "domain")
        for kind in ("time_scales", "error_scales"):
            fn = getattr(model, kind)
            if fn is None:
                self.functions.append(f"static int pg_{kind}({ARGS['scales']})\n{{\n    (void)p; (void)out; (void)m;\n"
                                      f"    *n = 0;\n    return PG_OK;\n}}\n")
            else:
                counts[kind] = self.function(f"pg_{kind}", ARGS["scales"], lambda fn=fn: fn(inp.p()),
                                             self._scales_leaf, kind.replace("_", " "))
        self.counts = counts
        return self._file(names)

    def _dispatch(self, name, args, call_args, ne):
        lines = [f"static int {name}(int k, {args})", "{", "    switch (k) {"]
        for k in range(ne):
            lines.append(f"    case {k}: return {name}_{k}({call_args});")
        lines += ["    default: (void)k;" if ne == 0 else "    default: break;", "    }"]
        lines += [f"    (void){a};" for a in call_args.split(", ")]
        lines += ["    pg_msg_clear(m);", '    pg_msg_str(m, "no such event");', "    return PG_RAISE;", "}", ""]
        return "\n".join(lines)

    def _file(self, out_names):
        model = self.model
        size = model_sizes(model)
        ne = size["EVENTS"]
        nte = size["TIME_EVENTS"]

        def strings(name, items):
            if not items:
                return f"static const char *const {name}[1] = {{0}};"
            return f"static const char *const {name}[] = {{{', '.join(c_string(s) for s in items)}}};"
        head = [
            f"/* {model.name}: generated by pogofmu.codegen.cmodel from the Python model (do not edit;",
            "   rebuilt by build_fmu.py). Every function does the Python code's operations in its order. */",
            '#include <math.h>', '#include "pg_model.h"', '#include "pg_support.h"', "",
        ]
        tail = [
            self._dispatch("pg_guard", ARGS["guard"], "t, x, q, u, p, g, m", ne),
            self._dispatch("pg_active", ARGS["active"], "q, on, m", ne),
            self._dispatch("pg_jump", ARGS["jump"], "t, x, q, u, p, x_new, q_new, m", ne),
            self._dispatch("pg_time_event", ARGS["time_event"], "p, at, every, m", nte),
            self._dispatch("pg_time_jump", ARGS["jump"], "t, x, q, u, p, x_new, q_new, m", nte),
            strings("TIME_EVENT_NAMES", [ev.name for ev in model.time_events]),
            strings("STATE_NAMES", [v.name for v in model.states]),
            strings("Q_NAMES", [k for k, _ in self.layout]),
            strings("INPUT_NAMES", [v.name for v in model.inputs]),
            strings("PARAMETER_NAMES", [par.name for par in model.parameters]),
            strings("OUTPUT_NAMES", out_names),
            strings("EVENT_NAMES", [ev.name for ev in model.events]),
            f"static const signed char EVENT_DIRECTION[] = {{{', '.join(str(ev.direction) for ev in model.events) or '0'}}};",
            "",
            f"const PgModel {ONE_MODEL} = {{",  # (its counts those of pg_sizes.h: model_sizes)
            f"    {c_string(model.name)}, {size['X']}, {size['Q']}, {size['U']}, {size['P']}, "
            f"{len(SOLVER_PARAMETERS)}, {size['Y']}, {size['EVENTS']},",
            "    STATE_NAMES, Q_NAMES, " + c_string("".join(k for _, k in self.layout)) + ", INPUT_NAMES, PARAMETER_NAMES,",
            "    " + c_string("".join("i" if par.integer else "f" for par in model.parameters)) + ",",
            "    OUTPUT_NAMES, EVENT_NAMES, EVENT_DIRECTION,",
            f"    {int(model.time_scales is not None)}, {int(model.error_scales is not None)},",
            "    pg_check_settings, pg_check, pg_initial, pg_flow, pg_guard, pg_active, pg_jump, pg_outputs, "
            "pg_domain, pg_time_scales, pg_error_scales, pg_flow_jvp, pg_outputs_jvp,",
            f"    {nte}, TIME_EVENT_NAMES, pg_time_event, pg_time_jump,",
            "};", "",
        ]
        tables = []
        for M, name in self.matrices.items():
            tables += matrix_table(name, M) + [""]
        return "\n".join(head + tables + self.functions + tail)


SIZES = (("X", "states"), ("U", "inputs"), ("P", "parameters"), ("EVENTS", "events"), ("Y", "outputs"),
         ("Q", "discrete state entries"), ("TIME_EVENTS", "time events"))


def model_sizes(model: HybridModel) -> Dict[str, int]:
    """The model's count of each engine size (``PG_MAX_<key>``): states, inputs, parameters,
    events, outputs and discrete state entries (the counts ``PG_MODEL`` declares)."""
    counts = (len(model.states), len(model.inputs), len(model.parameters), len(model.events), len(model.outputs),
              len(discrete_layout(model)), len(model.time_events))
    return {key: n for (key, _), n in zip(SIZES, counts)}


def sizes_header(model: HybridModel) -> str:
    """``pg_sizes.h`` of a native FMU: every array of the engine sized to the model's counts (at
    least 1), so that an instance and each of its FMU states hold only what the model uses, and
    ``PG_NX``, ``PG_NQ`` and ``PG_NY``, its numbers of states, discrete entries and outputs (pg_pairs.h,
    ``PG_N``), and ``PG_ONE_MODEL``, the name of its ``PgModel``: the engine then calls the model's
    functions directly (pg_engine.c, ``MODEL``), which a link-time optimized build inlines."""
    lines = ["/* generated by pogofmu.codegen.cmodel: the engine's arrays sized for " + model.name + " */",
             "#ifndef PG_SIZES_H", "#define PG_SIZES_H"]
    lines += [f"#define PG_MAX_{key} {max(n, 1)}" for key, n in model_sizes(model).items()]
    lines += [f"#define {key} {value}" for key, value in specialization(model).items()]
    return "\n".join(lines + ["#endif", ""])


def specialization(model: HybridModel) -> Dict[str, object]:
    """What a native FMU's engine is built for besides its sizes (``sizes_header``; a C program built
    like it takes them as ``-D`` defines): the model's exact counts and ``PG_ONE_MODEL``, the name of
    its ``PgModel``, whose functions the engine then calls by name (pg_engine.c, ``MODEL``); and
    ``PG_STATE_OUTPUTS_EXACT`` where every output of a state's name is that state, as generated."""
    exact = {"PG_STATE_OUTPUTS_EXACT": 1} if state_outputs_exact(model) else {}
    return {**exact_counts(model), "PG_ONE_MODEL": ONE_MODEL, **exact}


def state_outputs_exact(model: HybridModel) -> bool:
    """Whether the generated outputs function assigns every output of a state's name the state itself,
    on every path (``y[j] = v;`` with ``const double v = x[i];``): then the engine's check of that rule
    at each point (docs/writing-models.md section 6) cannot fail and is compiled out. Any other form,
    a computed value or a path the reading does not recognize, keeps the check."""
    import re

    states = {v.name: i for i, v in enumerate(model.states)}
    pairs = [(j, states[v.name]) for j, v in enumerate(model.outputs) if v.name in states]
    if not pairs:
        return True
    source = generate(model)
    start = source.find("static int pg_outputs(")
    if start < 0:
        return False
    body = source[start:source.find("\n}\n", start)]
    for j, i in pairs:
        assigned = re.findall(rf"\by\[{j}\] = (\w+);", body)
        if not assigned or any(not re.search(rf"const double {v} = x\[{i}\];", body) for v in assigned):
            return False
    return True


def exact_counts(model: HybridModel) -> Dict[str, int]:
    """The model's exact numbers of states, discrete entries and outputs (``PG_NX``, ``PG_NQ``,
    ``PG_NY``): with them as constants the engine's loops over them and its copies of them are
    unrolled and vectorized by the compiler (the same operations, the same bits)."""
    return {"PG_NX": len(model.states), "PG_NQ": len(discrete_layout(model)), "PG_NY": len(model.outputs)}


@once_per_model
def generate(model: HybridModel) -> str:
    """The C source of ``model`` (``PG_MODEL``); a model is traced once (an export checks it, then
    builds its FMI 2.0 and 3.0 FMUs from the same C)."""
    return ModelWriter(model).write()


def main(argv=None):
    from pogofmu.runtime.models import get

    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m pogofmu.codegen.cmodel <Model>", file=sys.stderr)
        return 2
    try:
        sys.stdout.write(generate(get(argv[0])))
    except (KeyError, TraceError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

__all__ = ["generate", "discrete_layout", "literal", "BOOL", "model_sizes", "sizes_header"]
