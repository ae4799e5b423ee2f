"""The mirror's global loop: one MIMO model that reads every segment's piston and gives every
segment's controller its command (docs/segmented-mirror.md).

The segments sit on a hexagonal grid of ``rings`` rings around a centre segment,
N = 1 + 3 rings (rings + 1) of them.  Each pair of neighbours shares an edge sensor that reads
the difference of their pistons, s_e = z_j - z_i (edge e = (i, j)): s = D z, D the E x N
incidence matrix.  Edge sensors see no global piston (D 1 = 0), so the relative pistons are the
least-squares reconstruction with zero mean,

    z_rel = argmin |D z_rel - s|^2  subject to  1' z_rel = 0,   i.e.  z_rel = L+ D' s,  L = D'D,

and the global piston is held by the target: each controller's command is

    r_i = z_target - G z_rel_i.

The pistons and commands are the arrays ``z`` and ``r`` of N (one FMI 3.0 array each; the
scalars ``z[i]``, ``r[i]`` in FMI 2.0), one model per ring count: :func:`reconstructor_model` builds it,
and the module defines the models for 1 and 2 rings.  Everything here runs in plain Python inside
the FMU (no numpy): the reconstruction matrix is a constant computed once at import, applied with
``fmath.matvec`` (in the native FMU a C table and a loop: at 12 rings the 469 x 1332 products
unrolled, with their derivatives, were C that gcc could not compile).
"""
import math

from pogofmu import HybridModel, Parameter, Variable, fmath, require, require_finite, require_nonnegative

AXIAL_DIRECTIONS = ((1, 0), (1, -1), (0, -1), (-1, 0), (-1, 1), (0, 1))


def hex_cells(rings):
    """Axial coordinates (q, r) of the segments: the centre, then each ring walked around."""
    cells = [(0, 0)]
    for k in range(1, rings + 1):
        q, r = -k, k  # k steps in direction 4 from the centre
        for d in range(6):
            for _ in range(k):
                cells.append((q, r))
                q, r = q + AXIAL_DIRECTIONS[d][0], r + AXIAL_DIRECTIONS[d][1]
    return cells


def hex_edges(cells):
    """The neighbour pairs (i, j), i < j: the edge sensors."""
    index = {c: i for i, c in enumerate(cells)}
    edges = []
    for i, (q, r) in enumerate(cells):
        for dq, dr in AXIAL_DIRECTIONS:
            j = index.get((q + dq, r + dr))
            if j is not None and i < j:
                edges.append((i, j))
    return edges


def hex_centres(cells, flat_to_flat=1.44):
    """The segments' centres (m) on the mirror, pointy-top hexagons ``flat_to_flat`` across."""
    a = flat_to_flat / math.sqrt(3.0)  # circumradius
    return [(math.sqrt(3.0) * a * (q + r / 2.0), 1.5 * a * r) for q, r in cells]


def _inverse(A):
    """The inverse of a small symmetric positive definite matrix (Gauss-Jordan, partial pivoting)."""
    n = len(A)
    M = [list(row) + [1.0 if i == j else 0.0 for j in range(n)] for i, row in enumerate(A)]
    for col in range(n):
        piv = max(range(col, n), key=lambda i: abs(M[i][col]))
        M[col], M[piv] = M[piv], M[col]
        d = M[col][col]
        M[col] = [v / d for v in M[col]]
        for i in range(n):
            if i != col and M[i][col] != 0.0:
                f = M[i][col]
                M[i] = [a - f * b for a, b in zip(M[i], M[col])]
    return [row[n:] for row in M]


def reconstruction_matrix(n, edges):
    """R (n x E) with z_rel = R s: R = L+ D', where L+ = (L + J/n)^-1 - J/n for a connected grid."""
    L = [[0.0] * n for _ in range(n)]
    for i, j in edges:
        L[i][i] += 1.0
        L[j][j] += 1.0
        L[i][j] -= 1.0
        L[j][i] -= 1.0
    Linv = _inverse([[L[i][j] + 1.0 / n for j in range(n)] for i in range(n)])
    Lp = [[Linv[i][j] - 1.0 / n for j in range(n)] for i in range(n)]
    # D' s: edge (i, j) reads z_j - z_i, so column e of D' is -1 at i, +1 at j
    return [[Lp[k][j] - Lp[k][i] for i, j in edges] for k in range(n)]


def reconstructor_model(rings):
    """The Reconstructor of a mirror of ``rings`` rings (``Reconstructor_R<rings>``)."""
    cells = hex_cells(rings)
    edges = hex_edges(cells)
    n = len(cells)
    R = fmath.Matrix(reconstruction_matrix(n, edges))  # a constant, checked once

    def relative(u):
        s = [u[j] - u[i] for i, j in edges]
        return fmath.matvec(R, s)  # the native FMU's C: one table and one loop, not N x E products

    def output_fn(t, x, q, u, p):
        rel = relative(u)
        out = {"r": [p.z_target - p.G * rel[k] for k in range(n)]}
        out["piston_rms"] = fmath.sqrt(sum(v * v for v in rel) / n)
        return out

    def check(p):
        require_finite(p)
        require_nonnegative(p, "G")
        require(p.G < 2.0, "G", p.G, "G < 2 (the global loop's gain on the relative pistons)")

    def initial(p):
        check(p)
        return [], {}

    return HybridModel(
        name=f"Reconstructor_R{rings}",
        description=f"edge-sensor reconstructor of a {rings}-ring segmented mirror ({n} segments, "
                    f"{len(edges)} edge sensors): least-squares relative pistons, global piston at the target",
        states=(),
        parameters=(Parameter("z_target", 5.0e-4, "m", "global piston the mirror is commanded to"),
                    Parameter("G", 0.5, "", "gain of the global loop on the reconstructed relative pistons")),
        inputs=(Variable("z", "m", "pistons of the segments", 0.0, shape=(n,)),),
        outputs=(Variable("r", "m", "piston commands of the segments", shape=(n,)),
                 Variable("piston_rms", "m", "rms of the reconstructed relative pistons (0: phased)")),
        flow=lambda t, x, q, u, p: [],
        events=(),
        initial=initial,
        output_fn=output_fn,
        check=check,
        feedthrough={"r": ("z",), "piston_rms": ("z",)},
        default_input=lambda t, p: {"z": [1e-4 * k for k in range(n)]},
        plots=((("r[1]", "r[2]", "r[3]"), ("piston_rms",)),),
        default_stop_time=0.01,
        default_step=1e-3,
    )


Reconstructor_R1 = reconstructor_model(1)
Reconstructor_R2 = reconstructor_model(2)
