"""The C of the Runge-Kutta pairs, generated from the tableaux
(:mod:`pogofmu.runtime.solver.tableaux`), term by term (zero coefficients skipped, sums left to
right).  The output is kept in the repository as ``fmu_src/native/engine/pg_pairs.c`` (the engine
compiles from its C files alone); a test regenerates it.

    python -m pogofmu.codegen.cpairs > pg_pairs.c
"""
from __future__ import annotations

import sys

from pogofmu.runtime.solver import tableaux as tab

from .cprint import literal


# the first line of every function: the number of states, a constant in a native FMU (pg_pairs.h)
N = "    n = PG_N(n);"


def _sum(coefs, stage, i="i"):
    """``c0*k0[i] + c2*k2[i] + ...`` (zero coefficients skipped, as pairs._lincomb)."""
    return " + ".join(f"{literal(c)}*{stage(j)}[{i}]" for j, c in enumerate(coefs) if c != 0.0)


def _stage_lines(A, C, first, last, y, t, fail):
    """The stages; a failed call of the model's function returns its own code (a model's error,
    PG_RAISE with the engine's message naming the function, passes as it is, not as PG_ARITH)."""
    out = []
    for s in range(first, last):
        expr = _sum(A[s][:s], lambda j: f"k{j}")
        out += [f"    for (int i = 0; i < n; ++i) tmp[i] = {y}[i] + h*({expr});",
                f"    if ((rc = fun(ctx, {t} + {literal(C[s])}*h, tmp, k{s}, m)) != PG_OK) {fail}"]
    return out


def _used(count, *combinations, always=()):
    """The stage indices below ``count`` that a combination uses (nonzero coefficient)."""
    used = set(always)
    for c in combinations:
        used |= {j for j, v in enumerate(c) if v != 0.0}
    return [j for j in range(count) if j in used]


def _const_stages(count, *combinations, always=()):
    return [f"    const double *k{j} = K + {j} * PG_MAX_X;" for j in _used(count, *combinations, always=always)]


def _stage_names(count):
    return [f"    double *k{j} = K + {j} * PG_MAX_X;" for j in range(count)]


def _step_function(title, name, A, B, C, ns):
    """``pg_<name>_step``: the stages of the tableau (A, C), the solution with the weights B, and
    the last stage (FSAL) at the step's end."""
    lines = [f"/* {title} */",
             f"int pg_{name}_step(PgFun fun, void *ctx, double t, const double *y, const double *f, double h, int n,",
             "                   double *y_new, double *f_new, double *K, PgMsg *m)", "{", N,
             "    double tmp[PG_MAX_X] = {0};", "    int rc;", *_stage_names(ns + 1),
             "    for (int i = 0; i < n; ++i) k0[i] = f[i];"]
    lines += _stage_lines(A, C, 1, ns, "y", "t", "return rc;")
    lines += [f"    for (int i = 0; i < n; ++i) y_new[i] = y[i] + h*({_sum(B, lambda j: f'k{j}')});",
              "    if ((rc = fun(ctx, t + h, y_new, f_new, m)) != PG_OK) return rc;",
              f"    for (int i = 0; i < n; ++i) k{ns}[i] = f_new[i];", "    return PG_OK;", "}", ""]
    return lines


def dopri5() -> str:
    A, B, C, E, P = tab.DOPRI5_A, tab.DOPRI5_B, tab.DOPRI5_C, tab.DOPRI5_E, tab.DOPRI5_P
    ns = len(B)
    lines = _step_function("DOPRI5: Dormand-Prince 5(4) with Shampine's dense output", "dopri5", A, B, C, ns)
    lines += ["double pg_dopri5_error_norm(const double *K, double h, const double *y, const double *y_new, double atol,",
              "                            double rtol, int n)", "{", N,
              *_const_stages(ns + 1, E),
              "    double acc = 0.0;", "    if (n == 0) return 0.0;",
              "    for (int i = 0; i < n; ++i) {",
              "        double ay = fabs(y[i]), an = fabs(y_new[i]);",
              f"        double e = h*({_sum(E, lambda j: f'k{j}')}) / (atol + rtol*(an > ay ? an : ay));",
              "        acc += e*e;", "    }", "    return sqrt(acc/n);", "}", ""]
    rows = [[P[j][r] for j in range(ns + 1)] for r in range(4)]
    lines += ["/* the four coefficient vectors of the continuous extension, from the stages */",
              "void pg_dopri5_dense(const double *PG_RESTRICT K, int n, double *PG_RESTRICT Q)", "{", N,
              *_const_stages(ns + 1, *rows),
              "    for (int i = 0; i < n; ++i) {"]
    for r in range(4):
        lines.append(f"        Q[{r} * PG_MAX_X + i] = {_sum(rows[r], lambda j: f'k{j}')};")
    lines += ["    }", "}", "",
              "void pg_dopri5_eval(const double *PG_RESTRICT Q, double t0, double h, const double *PG_RESTRICT y0, double t, int n,",
              "                    double *PG_RESTRICT out)", "{", N, "    const double x = (t - t0) / h;", "    const double hx = h * x;",
              "    for (int i = 0; i < n; ++i)",
              "        out[i] = y0[i] + hx * (Q[i] + x * (Q[PG_MAX_X + i] + x * (Q[2 * PG_MAX_X + i] + x * "
              "Q[3 * PG_MAX_X + i])));", "}", ""]
    return "\n".join(lines)


def dop853() -> str:
    A, B, C = tab.DOP853_A, tab.DOP853_B, tab.DOP853_C
    ns, nx = tab.DOP853_N_STAGES, tab.DOP853_N_STAGES_EXTENDED
    lines = _step_function("DOP853: Prince-Dormand 8(5,3) with the 7th-order dense output of Hairer, Norsett & Wanner",
                           "dop853", A, B, C, ns)
    lines += ["double pg_dop853_error_norm(const double *K, double h, const double *y, const double *y_new, double atol,",
              "                            double rtol, int n)", "{", N,
              *_const_stages(ns + 1, tab.DOP853_E5, tab.DOP853_E3),
              "    double n5 = 0.0, n3 = 0.0;", "    if (n == 0) return 0.0;",
              "    for (int i = 0; i < n; ++i) {",
              "        double ay = fabs(y[i]), an = fabs(y_new[i]);",
              "        double sc = atol + rtol*(an > ay ? an : ay);",
              f"        double a = ({_sum(tab.DOP853_E5, lambda j: f'k{j}')}) / sc;",
              f"        double b = ({_sum(tab.DOP853_E3, lambda j: f'k{j}')}) / sc;",
              "        n5 += a*a;", "        n3 += b*b;", "    }",
              "    if (n5 == 0.0) return 0.0;", "    return fabs(h) * n5 / sqrt((n5 + 0.01*n3) * n);", "}", ""]
    # dense output (Hairer's contd8): three more stages from (t0, y0), then seven coefficient vectors
    lines += ["/* the seven coefficient vectors of the continuous extension (three more stages) */",
              "int pg_dop853_dense(PgFun fun, void *ctx, double t0, const double *y0, const double *y1, double h,",
              "                    const double *K, int n, double *Q, PgMsg *m)", "{", N,
              "    double tmp[PG_MAX_X] = {0}, X[3][PG_MAX_X];", "    int rc;",
              *_const_stages(ns + 1, *(row[:ns + 1] for row in A[ns + 1:nx]), *(d[:ns + 1] for d in tab.DOP853_D),
                             always=(0, ns)),
              *[f"    double *k{j} = X[{j - ns - 1}];" for j in range(ns + 1, nx)]]
    lines += _stage_lines(A, C, ns + 1, nx, "y0", "t0", "return rc;")
    lines += ["    for (int i = 0; i < n; ++i) {",
              "        const double f0 = y1[i] - y0[i];",
              "        Q[i] = f0;",
              "        Q[PG_MAX_X + i] = h*k0[i] - f0;",
              f"        Q[2 * PG_MAX_X + i] = 2.0*f0 - h*(k0[i] + k{ns}[i]);"]
    for r in range(4):
        lines.append(f"        Q[{3 + r} * PG_MAX_X + i] = h*({_sum(tab.DOP853_D[r], lambda j: f'k{j}')});")
    lines += ["    }", "    return PG_OK;", "}", "",
              "void pg_dop853_eval(const double *PG_RESTRICT Q, double t0, double h, const double *PG_RESTRICT y0, double t, int n,",
              "                    double *PG_RESTRICT out)", "{", N, "    const double x = (t - t0) / h;", "    const double w = 1.0 - x;",
              "    for (int i = 0; i < n; ++i) {",
              "        const double *q = Q + i;",
              "        out[i] = y0[i] + x * (q[0] + w * (q[PG_MAX_X] + x * (q[2 * PG_MAX_X] + w * (q[3 * PG_MAX_X]"
              " + x * (q[4 * PG_MAX_X] + w * (q[5 * PG_MAX_X] + x * q[6 * PG_MAX_X]))))));",
              "    }", "}", ""]
    return "\n".join(lines)


def generate() -> str:
    return "\n".join([
        "/* The Runge-Kutta pairs of the engine: generated by pogofmu.codegen.cpairs from the tableaux",
        "   (pogofmu/runtime/solver/tableaux.py), term by term (do not edit; regenerate with",
        "   python -m pogofmu.codegen.cpairs > fmu_src/native/engine/pg_pairs.c). */",
        "#include <math.h>", '#include "pg_pairs.h"', "", dopri5(), dop853()])


if __name__ == "__main__":
    sys.stdout.write(generate())
