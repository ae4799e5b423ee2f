"""``pogofmu mirror``: the SSP system of a segmented mirror of R rings (docs/segmented-mirror.md).

    pogofmu mirror --rings 1 --out mirror.ssp                       # FMI 2.0 in SSP 1.0 (libcosim)
    pogofmu mirror --rings 2 --fmi 3 --backend native --out m.ssp  # FMI 3.0 in SSP 2.0

N = 1 + 3 R (R + 1) segments on a hexagonal grid, each an ``Actuator_i`` (MirrorActuator) with
its ``Controller_i`` (SegmentController), and one ``Reconstructor`` (Reconstructor_R<R>): 2 N + 1
components.  The model files are the ones of ``examples/segmented_mirror/``; they are exported
here, as ``pogofmu export`` does (:class:`pogofmu.exporter.Exporter`), into a temporary folder and
packed with them (:func:`pogofmu.exporter.pack_ssp`).  The Reconstructor of a ring count the
example file does not define at module level is a two-line model file written beside it
(``MODEL = reconstructor_model(R)``).

Parameters: one set per component (libcosim applies a component's first ParameterBinding
only): ``resources/actuator_<i>.ssv`` and ``controller_<i>.ssv`` hold the values every segment
shares (ACTUATOR, CONTROLLER) and the segment's own, ``reconstructor.ssv`` the reconstructor's.
The segment's own values are the initial piston ``z_0`` (the initial misphasing; the controller's filter starts there too)
and the gust amplitude ``A_w``, which grows linearly across the mirror (``A_W_EDGE x / x_max``),
so the outer segments on one side are pushed into their upper stops and those on the other side
into their lower stops.

``python -m pogofmu.studies.mirror demo DIR`` (``tasks.py run``) builds the 1-ring system, runs it
with ``pogofmu ssp run`` and draws the pistons over time and hexagon maps of them.
"""
from __future__ import annotations

import argparse
import importlib.util
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path
from xml.sax.saxutils import quoteattr

def _example_folder() -> Path:
    """The mirror's model files: the copy an installed package carries (the package build copies
    ``examples/segmented_mirror/*.py`` into ``pogofmu/studies/segmented_mirror/``), else the
    checkout's ``examples/segmented_mirror/``."""
    installed = Path(__file__).resolve().parent / "segmented_mirror"
    if (installed / "reconstructor.py").is_file():
        return installed
    return Path(__file__).resolve().parents[3] / "examples" / "segmented_mirror"


EXAMPLE = _example_folder()
MODEL_FILES = ("mirror_actuator.py", "segment_controller.py", "reconstructor.py")
DEFINED_RINGS = (1, 2)  # the Reconstructor_R<R> that reconstructor.py defines at module level

# the parameters every segment shares: name -> (value, unit); the FMUs' own defaults except
# where the mirror differs (the gust's timing)
ACTUATOR = {"m": (83.0, "kg"), "k": (1.2e4, "N/m"), "c": (50.0, "N.s/m"), "k_m": (2.0e3, "N/m"),
            "beta": (200.0, "1/(m.s)"), "z_s": (2.0e-3, "m"), "K": (1.0e8, "N/m^n"), "c_r": (0.5, ""),
            "d0dot": (0.01, "m/s"), "t_g": (0.3, "s"), "T_g": (0.4, "s")}
CONTROLLER = {"K_p": (3.3e5, "N/m"), "K_i": (4.0e6, "N/(m.s)"), "K_d": (7.0e3, "N.s/m"), "T_f": (1.0e-3, "s"),
              "T_t": (0.04, "s"), "F_max": (25.0, "N"), "locate_saturation": (0, "")}
RECONSTRUCTOR = {"z_target": (5.0e-4, "m"), "G": (0.5, "")}
SHARED = {**ACTUATOR, **CONTROLLER, **RECONSTRUCTOR}
A_W_EDGE = 90.0     # N: gust amplitude at the mirror's outermost column (> F_max + (k + k_m) z_s = 53 N)
MISPHASE = 1.0e-4   # m: amplitude of the initial misphasing
STOP_TIME = 1.5     # s: the gust is over at 0.7 s; the loops then settle


class MirrorError(Exception):
    """A mistake of the command line or a failure to build: one line."""


def segment_count(rings: int) -> int:
    return 1 + 3 * rings * (rings + 1)


def load_example(folder: Path = EXAMPLE):
    """The example's reconstructor module on the host (its hexagonal grid)."""
    path = folder / "reconstructor.py"
    if not path.is_file():
        raise MirrorError(f"the mirror's model files are not found: no {path} (a checkout of pogofmu has them in "
                          f"examples/segmented_mirror/, an installed package in pogofmu/studies/segmented_mirror/)")
    spec = importlib.util.spec_from_file_location("_pogofmu_mirror_reconstructor", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def segment_parameters(rings: int, grid):
    """``[(z_0, A_w)]`` of the segments: a deterministic misphasing within +-MISPHASE, and the gust
    linear across the mirror (x the segment's centre)."""
    cells = grid.hex_cells(rings)
    xy = grid.hex_centres(cells)
    x_max = max(abs(x) for x, _ in xy) or 1.0
    return [(MISPHASE * math.sin(2.0 + 2.4 * i), A_W_EDGE * x / x_max) for i, (x, _) in enumerate(xy)]


# ---------------------------------------------------------------------------------------------
# the .ssd and .ssv files (SSP 1.0; pack_ssp makes SSP 2.0 of them for FMI 3.0)
# ---------------------------------------------------------------------------------------------

def _connector(name, kind, unit=None, integer=False, size=None):
    """One ssd:Connector; ``size``: an array of that many elements (SSP 2.0 ssc:Dimension)."""
    dim = "" if size is None else f'<ssc:Dimension size="{size}"/>'
    if integer:
        return f'<ssd:Connector name="{name}" kind="{kind}"><ssc:Integer/>{dim}</ssd:Connector>'
    return f'<ssd:Connector name="{name}" kind="{kind}"><ssc:Real unit={quoteattr(unit)}/>{dim}</ssd:Connector>'


def _component(name, source, connectors, bindings):
    lines = [f'      <ssd:Component name="{name}" source="resources/{source}.fmu" '
             f'type="application/x-fmu-sharedlibrary">', "        <ssd:Connectors>"]
    lines += [f"          {c}" for c in connectors]
    lines += ["        </ssd:Connectors>", "        <ssd:ParameterBindings>"]
    lines += [f'          <ssd:ParameterBinding source="resources/{b}.ssv"/>' for b in bindings]
    lines += ["        </ssd:ParameterBindings>", "      </ssd:Component>"]
    return lines


UNITS = {"m": {"m": 1}, "m/s": {"m": 1, "s": -1}, "N": {"kg": 1, "m": 1, "s": -2}, "kg": {"kg": 1},
         "N/m": {"kg": 1, "s": -2}, "N.s/m": {"kg": 1, "s": -1}, "s": {"s": 1}, "1/(m.s)": {"m": -1, "s": -1},
         "N/(m.s)": {"kg": 1, "s": -3}, "m.s": {"m": 1, "s": 1}}


def _units(prefix, names):
    lines = [f"  <{prefix}:Units>"]
    for u in sorted(n for n in names if n in UNITS):
        base = " ".join(f'{k}="{v}"' for k, v in UNITS[u].items())
        lines.append(f'    <ssc:Unit name={quoteattr(u)}><ssc:BaseUnit {base}/></ssc:Unit>')
    return lines + [f"  </{prefix}:Units>"]


def system_structure(rings: int, grid, fmi: int = 2) -> str:
    """The .ssd (SSP 1.0; pack_ssp makes SSP 2.0 of it for FMI 3.0). The Reconstructor's pistons and
    commands: FMI 2.0's scalars ``z[i]``, ``r[i]``; with ``fmi = 3`` the arrays ``z`` and ``r``, each
    segment connected to its element (``endIndices`` / ``startIndices``, 1-based)."""
    name = f"Mirror_R{rings}"
    cells = grid.hex_cells(rings)
    n = len(cells)
    edges = grid.hex_edges(cells)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f"<!-- {name}: a segmented mirror of {rings} ring(s), {n} segments on a hexagonal grid with "
             f"{len(edges)} edge sensors, generated by pogofmu mirror (docs/segmented-mirror.md).",
             "     Actuator_i.z -> Reconstructor.z[i] and Controller_i.z; Reconstructor.r[i] -> Controller_i.r;",
             "     Controller_i.F -> Actuator_i.F.  Segment i's centre (axial q, r): "
             + ", ".join(f"{i + 1}: {c}" for i, c in enumerate(cells)) + " -->",
             '<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"',
             '                                xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"',
             f'                                version="1.0" name="{name}" generationTool="pogofmu mirror">',
             f'  <ssd:System name="{name}" description="segmented mirror: {n} actuators with their PID loops '
             f'and one edge-sensor reconstructor">',
             "    <ssd:Elements>"]
    for i in range(1, n + 1):
        lines += _component(f"Actuator_{i}", "MirrorActuator",
                            [_connector("F", "input", "N"), _connector("z", "output", "m"),
                             _connector("zdot", "output", "m/s"), _connector("F_stop", "output", "N"),
                             _connector("mode", "output", integer=True), _connector("F_w", "output", "N")],
                            (f"actuator_{i}",))
    for i in range(1, n + 1):
        lines += _component(f"Controller_{i}", "SegmentController",
                            [_connector("r", "input", "m"), _connector("z", "input", "m"),
                             _connector("F", "output", "N"), _connector("F_u", "output", "N")],
                            (f"controller_{i}",))
    if fmi == 3:
        arrays = [_connector("z", "input", "m", size=n), _connector("r", "output", "m", size=n)]
    else:
        arrays = ([_connector(f"z[{i}]", "input", "m") for i in range(1, n + 1)]
                  + [_connector(f"r[{i}]", "output", "m") for i in range(1, n + 1)])
    lines += _component("Reconstructor", f"Reconstructor_R{rings}",
                        arrays + [_connector("piston_rms", "output", "m")], ("reconstructor",))
    lines += ["    </ssd:Elements>", "    <ssd:Connections>"]

    def conn(a, ac, b, bc):
        if fmi == 3 and "[" in ac + bc:  # an element of an array connector: its 1-based index
            (ac, ai), (bc, bi) = (c.rstrip("]").split("[") if "[" in c else (c, None) for c in (ac, bc))
            return (f'      <ssd:Connection startElement="{a}" startConnector="{ac}"'
                    + (f' startIndices="{ai}"' if ai else "") + f' endElement="{b}" endConnector="{bc}"'
                    + (f' endIndices="{bi}"' if bi else "") + "/>")
        return (f'      <ssd:Connection startElement="{a}" startConnector="{ac}" endElement="{b}" '
                f'endConnector="{bc}"/>')

    lines += [conn(f"Actuator_{i}", "z", "Reconstructor", f"z[{i}]") for i in range(1, n + 1)]
    for i in range(1, n + 1):
        lines += [conn(f"Actuator_{i}", "z", f"Controller_{i}", "z"),
                  conn("Reconstructor", f"r[{i}]", f"Controller_{i}", "r"),
                  conn(f"Controller_{i}", "F", f"Actuator_{i}", "F")]
    lines += ["    </ssd:Connections>", "  </ssd:System>"]
    lines += _units("ssd", ("m", "m/s", "N"))
    lines += [f'  <ssd:DefaultExperiment startTime="0" stopTime="{STOP_TIME:g}"/>',
              "</ssd:SystemStructureDescription>"]
    return "\n".join(lines) + "\n"


def parameter_set(name: str, values: dict, comment: str) -> str:
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', f"<!-- {comment} -->",
             '<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"',
             '                  xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"',
             f'                  version="1.0" name="{name}">', "  <ssv:Parameters>"]
    for pname, (value, unit) in values.items():
        u = f" unit={quoteattr(unit)}" if unit else ""
        kind = "Integer" if isinstance(value, int) else "Real"
        lines.append(f'    <ssv:Parameter name="{pname}"><ssv:{kind} value="{value!r}"{u}/></ssv:Parameter>')
    lines += ["  </ssv:Parameters>"] + _units("ssv", {u for _, u in values.values()})
    return "\n".join(lines + ["</ssv:ParameterSet>"]) + "\n"


def write_system(folder: Path, rings: int, grid, fmi: int = 2) -> Path:
    """``folder/Mirror_R<rings>/`` with SystemStructure.ssd and the parameter sets."""
    system = folder / f"Mirror_R{rings}"
    system.mkdir(parents=True)
    (system / "SystemStructure.ssd").write_text(system_structure(rings, grid, fmi))
    # one set per component, the shared values with the segment's own: libcosim applies only a
    # component's first ParameterBinding, so each component has one
    (system / "reconstructor.ssv").write_text(parameter_set("reconstructor", RECONSTRUCTOR,
                                                            "the reconstructor's parameters"))
    for i, (z0, aw) in enumerate(segment_parameters(rings, grid), start=1):
        (system / f"actuator_{i}.ssv").write_text(parameter_set(
            f"actuator_{i}", {**ACTUATOR, "z_0": (z0, "m"), "A_w": (aw, "N")},
            f"segment {i}'s actuator: the shared values, its initial piston and its gust amplitude"))
        (system / f"controller_{i}.ssv").write_text(parameter_set(
            f"controller_{i}", {**CONTROLLER, "z_0": (z0, "m")},
            f"segment {i}'s controller: the shared values; its filter starts at the piston"))
    return system


# ---------------------------------------------------------------------------------------------
# exporting and packing
# ---------------------------------------------------------------------------------------------

def model_sources(folder: Path, rings: int):
    """The three models, loaded from the model files copied into ``folder``."""
    from pogofmu.exporter import load_model_file

    sources = load_model_file(folder / "mirror_actuator.py") + load_model_file(folder / "segment_controller.py")
    name = f"Reconstructor_R{rings}"
    if rings in DEFINED_RINGS:
        return sources + load_model_file(folder / "reconstructor.py", names=[name])
    path = folder / f"reconstructor_r{rings}.py"
    path.write_text(f'"""The Reconstructor of a {rings}-ring mirror."""\nfrom reconstructor import reconstructor_model\n\n'
                    f"MODEL = reconstructor_model({rings})\n")
    return sources + load_model_file(path)


def generate(rings: int, out: Path, fmi: int = 2, backend: str = "python", log=lambda *a: None,
             example: Path = EXAMPLE) -> Path:
    """Export the FMUs, write the system and pack it as ``out`` (an .ssp); returns ``out``."""
    from pogofmu.exporter import Exporter, pack_ssp

    grid = load_example(example)
    with tempfile.TemporaryDirectory(prefix="pogofmu_mirror_") as tmp:
        tmp = Path(tmp)
        models = tmp / "models"
        models.mkdir()
        for name in MODEL_FILES:
            shutil.copy(example / name, models / name)
        fmus = tmp / "fmus"
        with Exporter(fmus, (fmi,), (backend,), log=log) as ex:
            for source in model_sources(models, rings):
                ex.export(source)
            if ex.refusals:
                raise MirrorError("; ".join(ex.refusals))
        system = write_system(tmp / "system", rings, grid, fmi)
        dest = fmus / "native" if backend == "native" else fmus
        packed = pack_ssp(system, dest, fmi3=fmi == 3)
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(packed, out)
    return out


def main(argv=None, prog="pogofmu mirror") -> int:
    ap = argparse.ArgumentParser(prog=prog, description="generate the SSP system of a segmented mirror: 1 + 3R(R+1) "
                                 "segments on a hexagonal grid, an actuator and a PID controller each, and one "
                                 "reconstructor (docs/segmented-mirror.md)")
    ap.add_argument("--rings", type=int, required=True, help="rings of segments around the centre one (>= 1)")
    ap.add_argument("--fmi", choices=("2", "3"), default="2", help="2: FMI 2.0 in SSP 1.0 (default); 3: FMI 3.0 in SSP 2.0")
    ap.add_argument("--backend", choices=("python", "native"), default="python",
                    help="python: Python-hosted FMUs (default); native: C generated from the models")
    ap.add_argument("--out", required=True, metavar="FILE.ssp", help="the package to write")
    args = ap.parse_args(argv)
    from pogofmu.exporter import BuildError, ModelFileError
    from pogofmu.exporter.export import one_line

    start = time.perf_counter()
    out = Path(args.out)
    try:
        if args.rings < 1:
            raise MirrorError(f"--rings {args.rings}: at least 1 ring (a mirror of 7 segments)")
        if out.suffix != ".ssp":
            raise MirrorError(f"--out {args.out}: the package's name ends in .ssp")
        if out.is_dir():
            raise MirrorError(f"--out {args.out} is a folder: name the .ssp file to write")
        generate(args.rings, out, int(args.fmi), args.backend)
    except (MirrorError, BuildError, ModelFileError) as exc:
        print(f"{prog}: {one_line(exc)}", file=sys.stderr)
        return 1 if not isinstance(exc, MirrorError) else 2
    except OSError as exc:
        print(f"{prog}: {exc.filename or args.out}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 - never a traceback: one line
        print(f"{prog}: unexpected {type(exc).__name__}: {one_line(exc)} -- a bug of pogofmu, please report it",
              file=sys.stderr)
        return 2
    n = segment_count(args.rings)
    print(f"{out}: Mirror_R{args.rings}, {n} segments, {2 * n + 1} FMUs (FMI {args.fmi}.0, {args.backend}, "
          f"SSP {'2.0' if args.fmi == '3' else '1.0'}) in {time.perf_counter() - start:.1f} s")
    return 0


# ---------------------------------------------------------------------------------------------
# the 1-ring demonstration (tasks.py run) and its figures
# ---------------------------------------------------------------------------------------------

MAP_TIMES = (0.0, 0.05, 0.5, STOP_TIME)  # s: the misphased start, the step, the gust's peak, the end


def read_csv(path: Path):
    import numpy as np

    with open(path) as f:
        names = f.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, k] for k, name in enumerate(names)}


def figures(csv: Path, rings: int, target: float = SHARED["z_target"][0]):
    """``pistons.png`` (every segment's piston over time, the stops and the target) and
    ``piston_map.png`` (the pistons on the hexagonal grid at MAP_TIMES), beside ``csv``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import RegularPolygon

    grid = load_example()
    cells = grid.hex_cells(rings)
    xy = grid.hex_centres(cells)
    res = read_csv(csv)
    t = res["time"]
    n = len(cells)
    z = [res[f"Actuator_{i}.z"] * 1e3 for i in range(1, n + 1)]
    z_s = SHARED["z_s"][0] * 1e3
    fig, ax = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for i in range(n):
        ax[0].plot(t, z[i], lw=1, label=f"segment {i + 1}")
    for level in (z_s, -z_s):
        ax[0].axhline(level, color="k", lw=0.8, ls="--")
    ax[0].axhline(target * 1e3, color="grey", lw=0.8, ls=":")
    ax[0].set_ylabel("piston z [mm]")
    ax[0].legend(ncol=4, fontsize=7)
    ax[0].set_title(f"Mirror_R{rings}: step command to {target * 1e3:g} mm, gust {SHARED['t_g'][0]:g}-"
                    f"{SHARED['t_g'][0] + SHARED['T_g'][0]:g} s (stops dashed)")
    ax[1].semilogy(t, res["Reconstructor.piston_rms"] * 1e9 + 1e-3)
    ax[1].set_ylabel("rms relative piston [nm]")
    ax[1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(csv.parent / "pistons.png", dpi=120)
    plt.close(fig)

    fig, axes = plt.subplots(1, len(MAP_TIMES), figsize=(4 * len(MAP_TIMES), 4.2))
    norm = matplotlib.colors.Normalize(-z_s, z_s)
    cmap = matplotlib.colormaps["coolwarm"]
    a = 1.44 / math.sqrt(3.0)
    for axm, when in zip(axes, MAP_TIMES):
        k = int(abs(t - when).argmin())
        for i, (x, y) in enumerate(xy):
            axm.add_patch(RegularPolygon((x, y), 6, radius=a * 0.97, facecolor=cmap(norm(z[i][k])), edgecolor="k"))
            axm.text(x, y, f"{z[i][k]:.3f}", ha="center", va="center", fontsize=7)
        span = max(max(abs(x), abs(y)) for x, y in xy) + a
        axm.set_xlim(-span, span)
        axm.set_ylim(-span, span)
        axm.set_aspect("equal")
        axm.set_axis_off()
        axm.set_title(f"t = {t[k]:.3f} s")
    fig.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap), ax=list(axes), label="piston [mm]", shrink=0.8)
    fig.savefig(csv.parent / "piston_map.png", dpi=120)
    plt.close(fig)
    return csv.parent / "pistons.png", csv.parent / "piston_map.png"


def demo(out_dir, rings: int = 1, step: float = 1e-3) -> int:
    """Generate the mirror, run it with ``pogofmu ssp run`` (events synchronized) and draw it."""
    import subprocess

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    ssp = out_dir / f"Mirror_R{rings}.ssp"
    rc = main(["--rings", str(rings), "--out", str(ssp)])
    if rc:
        return rc
    start = time.perf_counter()
    rc = subprocess.call([sys.executable, "-m", "pogofmu.cli", "ssp", "run", str(ssp), "--step", repr(step),
                          "--out", str(out_dir), "--quiet"])
    if rc:
        return rc
    print(f"Mirror_R{rings}: run in {time.perf_counter() - start:.1f} s")
    for fig in figures(out_dir / "default.csv", rings):
        print(f"wrote {fig}")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["demo"] and len(sys.argv) == 3:
        sys.exit(demo(sys.argv[2]))
    sys.exit(main())
