"""The native FMUs beyond the x86-64 Linux binary: aarch64 Linux under qemu, Windows under wine,
macOS checked, and the source FMU.

Every binary is cross-compiled by the build with zig (the ziglang package), -ffp-contract=off and
no fast-math on every target, so every platform that runs here gives x86-64 Linux's bits:

* aarch64 Linux: ``binaries/aarch64-linux/<Model>.so`` (both FMI versions); the tests' C hosts
  (tests/c_host/fmi2_host.c, fmi3_host.c), cross-compiled for aarch64 with zig, run every default
  experiment under qemu-user (``qemu-aarch64 -L /usr/aarch64-linux-gnu``, Debian: qemu-user and
  libc6-arm64-cross); the same events, every output column within 1e-12 relative of the x86-64
  Linux binary's, and reported as xfailed, naming the first difference, where not to the bit.
  The hosts are compiled with -ffp-contract=off too (support.HOST_CFLAGS): they compute the step
  sizes they pass, and a fused ``t - (k - 1) * h`` gave the aarch64 FMUs steps 1 ulp off.
* Windows: ``binaries/win64/<Model>.dll`` (FMI 2.0), ``binaries/x86_64-windows/<Model>.dll``
  (FMI 3.0) need nothing but Windows' own KERNEL32 and UCRT (api-ms-win-crt-*) and export the FMI
  functions only (and their C stepping loop for the sweeps, ``pogofmu_fmi2_run_grid`` /
  ``pogofmu_fmi3_run_grid``); the C hosts, cross-compiled with zig, run every default experiment
  under wine — FMI 2.0 co-simulation, FMI 3.0 co-simulation with event mode and early return, and
  FMI 3.0 model exchange — compared with the x86-64 Linux binary's outputs in the same way.
  The DLL imports every math function of inexact result its sources call from the UCRT
  (pg_crt_math.h), not zig's compiler runtime's, whose exp differs from the C library's.
  (No fused multiply-add in the model's and engine's arithmetic; what can still differ at the last
  bit is the C library's exp, log, pow, sin, ... themselves, which no standard requires to round
  alike: glibc's aarch64 build, the UCRT — and glibc's x86-64 exp, log, pow pick an FMA variant on
  a CPU with FMA, whose bits differ from its own plain variant's and the UCRT's in rare arguments.)
* macOS cannot run here: ``binaries/x86_64-darwin/`` and ``binaries/aarch64-darwin/`` (FMI 3.0)
  and FMI 2.0's universal ``binaries/darwin64/`` are read with a small Mach-O reader (below): the
  right architecture, every fmi2*/fmi3* function of the standard's header exported, and no
  undefined symbol bound to anything but libSystem.
* Source FMU: ``sources/`` and ``modelDescription.xml`` alone — the binaries deleted — build with
  the system compiler and nothing else (no include path outside the FMU, an empty environment),
  with fmpy's own source-FMU build (CMake; FMI 3.0 from ``sources/buildDescription.xml``) and with
  fmpy's ``compile_platform_binary``; the libraries built give the shipped binary's outputs.

The tests that need qemu-user, libc6-arm64-cross, wine, CMake or ziglang are skipped, naming what
is missing, without them; ``.ci/run`` installs the Debian packages (ziglang is a dependency), and
under ``CI=true`` a missing one fails the test.
"""
import os
import platform
import shutil
import struct
import subprocess
import zipfile
from pathlib import Path

import pytest

from pogofmu import exporter as build
from pogofmu.codegen.build import PLATFORMS, zig_cc
from support import HOST_CFLAGS, compile_c_host, fmu_path, needs
from test_portability import BARE_ENV, C_HOST_SOURCE, outputs_of, run_c_host

FMUS = build.model_names()
ZIG = zig_cc("native") is not None
WINE = next((w for w in (shutil.which("wine64"), "/usr/lib/wine/wine64", shutil.which("wine"))
             if w and os.access(w, os.X_OK)), None)
QEMU = shutil.which("qemu-aarch64") or shutil.which("qemu-aarch64-static")
ARM64_SYSROOT = Path("/usr/aarch64-linux-gnu")
EXACT = platform.machine() in ("x86_64", "AMD64")  # no FMA in the baseline instruction set



def _description(path):
    from fmpy import read_model_description

    return read_model_description(str(path))


def _extract(name, folder, keep=lambda member: True, fmi=2):
    with zipfile.ZipFile(fmu_path(f"native/{'fmi3/' if fmi == 3 else ''}{name}")) as z:
        for member in z.namelist():
            if keep(member):
                z.extract(member, folder)
    return folder


def _experiment(md):
    return float(md.defaultExperiment.stopTime), float(md.defaultExperiment.stepSize)


@pytest.fixture(scope="module")
def linux_host(tmp_path_factory):
    return compile_c_host(C_HOST_SOURCE, tmp_path_factory.mktemp("linux_host") / "fmi2_host")


@pytest.fixture(scope="module")
def linux_runs(tmp_path_factory, linux_host):
    """Each native FMU's default experiment with its shipped Linux binary: (description, rows)."""
    cache = {}

    def get(name):
        if name not in cache:
            folder = _extract(name, tmp_path_factory.mktemp(f"linux_{name}"))
            md = _description(folder)
            rc, rows, err = run_c_host(linux_host, folder, name, *_experiment(md), outputs_of(name), md=md)
            assert rc == 0, err[-2000:]
            cache[name] = (md, rows)
        return cache[name]
    return get


def _assert_same_run(got, ref, name, exact):
    assert len(got) == len(ref), f"{name}: {len(got)} rows, expected {len(ref)}"
    for a, b in zip(got, ref):
        for key, want in b.items():
            have = a[key]
            if exact or isinstance(want, int):
                assert have == want, f"{name}.{key} at t = {b['time']}: {have!r} != {want!r}"
            else:
                assert abs(have - want) <= 1e-12 * max(1.0, abs(want)), f"{name}.{key} at t = {b['time']}"


# ---- cross-compiled C hosts ---------------------------------------------------------------------

def _cross_compile(source, exe, target):
    """A C host of tests/c_host/ compiled for ``target`` (a zig target) with zig cc."""
    extra = ["-D__USE_MINGW_ANSI_STDIO=1"] if "windows" in target else ["-ldl"]
    subprocess.run([*zig_cc(target), *HOST_CFLAGS, f"-I{build.fmi_headers()}", str(source), "-o", str(exe), *extra],
                   check=True)
    return exe


WINDOWS = PLATFORMS["x86_64-windows"][1]
AARCH64 = PLATFORMS["aarch64-linux"][1]


def _wine_env(tmp_path_factory):
    base = tmp_path_factory.getbasetemp()
    return dict(BARE_ENV, WINEPREFIX=str(base / "wineprefix"), WINEDEBUG="-all", HOME=str(base))


QEMU_PREFIX = (QEMU, "-L", str(ARM64_SYSROOT))


def _foreign(kind, tmp_path_factory):
    """How to run a cross-compiled host: (zig target, command prefix, path of a file for it, env)."""
    if kind == "wine":
        return WINDOWS, (WINE,), lambda p: Path("Z:" + str(p)), _wine_env(tmp_path_factory)
    return AARCH64, QEMU_PREFIX, lambda p: p, BARE_ENV


FOREIGN = ["wine", "qemu"]
PREREQUISITES = {
    "wine": [(ZIG, "ziglang (PyPI: ziglang, a dependency of pogofmu)"), (WINE is not None, "wine64 (Debian: wine64)")],
    "qemu": [(ZIG, "ziglang (PyPI: ziglang, a dependency of pogofmu)"),
             (QEMU is not None, "qemu-aarch64 (Debian: qemu-user)"),
             ((ARM64_SYSROOT / "lib" / "ld-linux-aarch64.so.1").exists(),
              "the aarch64 C library (Debian: libc6-arm64-cross)")],
}


def _require(kind):
    """Skip (under CI=true: fail) through support.needs when a prerequisite of ``kind`` is missing."""
    for available, what in PREREQUISITES[kind]:
        needs(available, what)(lambda: None)()


@pytest.fixture(scope="module")
def foreign_hosts(tmp_path_factory):
    """The FMI 2.0 / 3.0 C hosts cross-compiled once per (kind, version)."""
    cache = {}

    def get(kind, fmi):
        if (kind, fmi) not in cache:
            target = _foreign(kind, tmp_path_factory)[0]
            source = C_HOST_SOURCE if fmi == 2 else FMI3_HOST
            exe = tmp_path_factory.mktemp(f"{kind}_host{fmi}") / (f"fmi{fmi}_host" + (".exe" if kind == "wine" else ""))
            cache[kind, fmi] = _cross_compile(source, exe, target)
        return cache[kind, fmi]
    return get


# ---- Windows and aarch64 Linux: the x86-64 Linux bits ----------------------------------------------

@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("name", FMUS)
def test_the_windows_binary_needs_only_windows_own_libraries(name, fmi, tmp_path):
    platform_dir = "win64" if fmi == 2 else "x86_64-windows"
    folder = _extract(name, tmp_path, lambda m: m.startswith(f"binaries/{platform_dir}/"), fmi=fmi)
    dll = folder / "binaries" / platform_dir / f"{name}.dll"
    assert dll.exists(), "every native FMU carries the Windows binary"
    # GNU objdump (mingw's, or Debian's, which reads PE too) prints the export table that is read below;
    # llvm-objdump -p prints no exports
    objdump = shutil.which("x86_64-w64-mingw32-objdump") or "objdump"
    text = subprocess.run([objdump, "-p", str(dll)], capture_output=True, text=True, check=True).stdout
    assert "[Ordinal/Name Pointer] Table" in text, f"{objdump} -p printed no export table of {dll.name}"
    imported = {line.split(":", 1)[1].strip() for line in text.splitlines() if "DLL Name:" in line}
    assert imported and all(d == "KERNEL32.dll" or d.startswith("api-ms-win-crt-") for d in imported), imported
    table = text[text.index("[Ordinal/Name Pointer] Table"):].splitlines()[1:]
    exported = [line.split("]", 1)[1].strip() for line in table if line.strip().startswith("[")]
    extensions = {f"pogofmu_fmi{fmi}_run_grid"}  # (the sweep's C loop, pogofmu.sweep)
    assert len(exported) >= 30 and all(e.startswith(f"fmi{fmi}") or e in extensions for e in exported), exported
    assert extensions <= set(exported)
    # every math function of inexact result that the C sources call is the UCRT's, imported, as the
    # Python-hosted FMU's is the C library's: none of zig's compiler runtime, which the linker reads
    # first (its exp differs from the C library's in the last bit: pg_crt_math.h)
    called = _math_called(_extract(name, tmp_path / "sources", lambda m: m.startswith("sources/"), fmi=fmi))
    math_dll = text[text.index("DLL Name: api-ms-win-crt-math-l1-1-0.dll"):].split("DLL Name:", 2)[1]
    imported = {line.split()[-1] for line in math_dll.splitlines()[2:] if line.strip()}
    assert called and called <= imported, sorted(called - imported)


# the C library's functions of inexact result that the engine may call (pg_support.c's wrappers)
INEXACT_MATH = ("exp", "log", "log10", "sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "cbrt",
                "pow", "atan2", "hypot")


def _math_called(folder):
    """The functions of INEXACT_MATH named in the C sources of ``folder/sources`` (comments and
    strings left out; a name passed to pg_support.c's wrapper macros counts)."""
    import re

    code = " ".join(p.read_text() for p in (folder / "sources").glob("*.c"))
    code = re.sub(r'"(\\.|[^"\\])*"', '""', re.sub(r"/\*.*?\*/|//[^\n]*", " ", code, flags=re.S))
    return {f for f in INEXACT_MATH if re.search(rf"\b{f}\b", code)}


@pytest.mark.parametrize("kind", FOREIGN)
@pytest.mark.parametrize("name", FMUS)
def test_the_foreign_binary_gives_the_x86_64_linux_bits(name, kind, tmp_path_factory, foreign_hosts, linux_runs):
    """FMI 2.0 co-simulation of the default experiment: the cross-compiled host loads the Windows
    DLL in wine (its own prefix, in the test's temporary folder) or the aarch64 library under
    qemu-user; the same events and, at every communication point, every output column within 1e-12
    relative of x86-64 Linux's; a run not equal to the bit is reported as xfailed with its first
    difference (the issue asks for the bits; docs/native.md says where and why they differ)."""
    _require(kind)
    md, ref = linux_runs(name)
    _, prefix, path, env = _foreign(kind, tmp_path_factory)
    folder = _extract(name, tmp_path_factory.mktemp(f"{kind}_{name}"))
    rc, rows, err = run_c_host(path(foreign_hosts(kind, 2)), path(folder), name, *_experiment(md), outputs_of(name),
                               md=md, env=env, prefix=prefix, timeout=600)
    assert rc == 0, err[-2000:]
    _assert_same_run(rows, ref, name, exact=False)  # the same events; every value within 1e-12 relative
    differing = _first_difference(rows, ref)
    if differing:  # only the C libraries' math functions may remain (docs/native.md, "Platforms"): shown as xfailed
        pytest.xfail(f"{name} under {kind}: not the x86-64 Linux bits (the C library's exp, log, pow, ... round "
                     f"otherwise: docs/native.md): {differing}")


def _first_difference(got, ref):
    """The first (time, column, value, x86-64 Linux's value) that differs in its bits, or None."""
    for a, b in zip(got, ref):
        for key, want in b.items():
            if a[key] != want:
                return b["time"], key, a[key], want
    return None


FMI3_HOST = C_HOST_SOURCE.parent / "fmi3_host.c"


def _fmi3_lines(exe, folder, name, md, events, step, env, prefix=()):
    """The FMI 3.0 C host's output: one line per event ("event,<t>,<flag>") and the end."""
    args = [*prefix, str(exe), str(folder), name, md.guid, repr(float(md.defaultExperiment.stopTime)), repr(step),
            str(events)]
    proc = subprocess.run(args, capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return [line.split(",") for line in proc.stdout.splitlines()]


@pytest.mark.parametrize("kind", FOREIGN)
@pytest.mark.parametrize("events, step", [(1, 1e-3), (2, 1e-5)], ids=["cs-event-mode", "me-euler"])
@pytest.mark.parametrize("name", ["PogoStick", "PogoStickSMA", "Penetrator"])
def test_the_fmi3_foreign_binary_gives_the_x86_64_linux_bits(name, events, step, kind, tmp_path_factory,
                                                              foreign_hosts):
    """FMI 3.0: co-simulation with event mode and early return (each lastSuccessfulTime an event
    time), and model exchange integrated by the host's own Euler steps (each event met); every
    line (event times printed with 17 digits) equals x86-64 Linux's."""
    _require(kind)
    base = tmp_path_factory.mktemp(f"fmi3_{name}_{events}_{kind}")
    linux = compile_c_host(FMI3_HOST, base / "fmi3_host")
    _, prefix, path, env = _foreign(kind, tmp_path_factory)
    folder = _extract(name, base / "fmu", fmi=3)
    md = _description(folder)
    ref = _fmi3_lines(linux, folder, name, md, events, step, BARE_ENV)
    got = _fmi3_lines(path(foreign_hosts(kind, 3)), path(folder), name, md, events, step, env, prefix=prefix)
    assert sum(1 for r in ref if r[0] == "event") >= 5
    assert len(got) == len(ref)
    for a, b in zip(got, ref):  # the same events; times within 1e-12 relative
        assert a[0] == b[0] and a[2:] == b[2:], (a, b)
        assert abs(float(a[1]) - float(b[1])) <= 1e-12 * max(1.0, abs(float(b[1]))), (a, b)
    if got != ref:  # only the C libraries' math functions may remain (docs/native.md, "Platforms"): shown as xfailed
        pytest.xfail(f"{name} under {kind}: not the x86-64 Linux bits (the C library's exp, log, pow, ... round "
                     f"otherwise: docs/native.md): {next(a for a, b in zip(got, ref) if a != b)}")


# ---- macOS: only checked ---------------------------------------------------------------------------

MACHO_CPU = {0x01000007: "x86_64", 0x0100000C: "arm64"}


def _macho_slices(data):
    """The thin Mach-O images of a file: itself, or each slice of a universal (fat) file."""
    magic = struct.unpack_from(">I", data)[0]
    if magic == 0xCAFEBABE:
        n = struct.unpack_from(">I", data, 4)[0]
        out = []
        for i in range(n):
            _, _, offset, size, _ = struct.unpack_from(">iiIII", data, 8 + 20 * i)
            out.append(data[offset:offset + size])
        return out
    return [data]


def _macho(data):
    """(architecture, dylibs loaded, exported names, undefined names with the dylib each binds to)
    of a thin 64-bit little-endian Mach-O, read from its load commands and symbol table."""
    magic, cputype, _, _, ncmds, _, _ = struct.unpack_from("<IiiIIII", data)
    assert magic == 0xFEEDFACF, hex(magic)
    offset, dylibs, symtab = 32, [], None
    for _ in range(ncmds):
        cmd, size = struct.unpack_from("<II", data, offset)
        if cmd in (0xC, 0x80000018, 0x8000001F):  # LC_LOAD_DYLIB, LC_LOAD_WEAK_DYLIB, LC_REEXPORT_DYLIB
            name_at = struct.unpack_from("<I", data, offset + 8)[0]
            dylibs.append(data[offset + name_at:offset + size].split(b"\0")[0].decode())
        elif cmd == 0x2:  # LC_SYMTAB
            symtab = struct.unpack_from("<IIII", data, offset + 8)
        offset += size
    symoff, nsyms, stroff, _ = symtab
    exported, undefined = set(), {}
    for i in range(nsyms):
        strx, ntype, _, desc, _ = struct.unpack_from("<IBBHQ", data, symoff + 16 * i)
        name = data[stroff + strx:].split(b"\0", 1)[0].decode()
        if ntype & 0xE0 or not ntype & 0x01:  # stabs, or not external
            continue
        if ntype & 0x0E == 0xE:  # N_SECT: defined here
            exported.add(name)
        elif ntype & 0x0E == 0:  # N_UNDF: bound to the dylib of its library ordinal
            ordinal = (desc >> 8) & 0xFF
            undefined[name] = dylibs[ordinal - 1] if 1 <= ordinal <= len(dylibs) else f"ordinal {ordinal}"
    return MACHO_CPU.get(cputype, hex(cputype)), dylibs, exported, undefined


def _standard_functions(fmi, model_exchange=True):
    """Every function the standard's header names (``#define fmi3X fmi3FullName(fmi3X)``); FMI 2.0
    without ``model_exchange``: not those of its sections "Functions for FMI2 for Model Exchange"."""
    import re

    text = (build.fmi_headers() / f"fmi{fmi}Functions.h").read_text()
    if not model_exchange:
        text, cut = re.subn(r"Functions for FMI2 for Model Exchange.*?Functions for FMI2 for Co-Simulation", "", text,
                            flags=re.S)
        assert cut, "the FMI 2.0 header has its Model Exchange section"
    return set(re.findall(rf"#define\s+(fmi{fmi}\w+)\s+fmi{fmi}FullName\(", text))


LIBSYSTEM = "/usr/lib/libSystem.B.dylib"


@pytest.mark.parametrize("folder, fmi, archs", [("darwin64", 2, ["x86_64", "arm64"]),
                                                ("x86_64-darwin", 3, ["x86_64"]), ("aarch64-darwin", 3, ["arm64"])])
@pytest.mark.parametrize("name", FMUS)
def test_the_macos_binary_is_of_its_architecture_and_needs_only_libsystem(name, folder, fmi, archs, tmp_path):
    path = f"binaries/{folder}/{name}.dylib"
    fmu = fmu_path(f"native/{'fmi3/' if fmi == 3 else ''}{name}")
    with zipfile.ZipFile(fmu) as z:
        data = z.read(path)
    functions = _standard_functions(fmi, _description(fmu).modelExchange is not None)
    assert len(functions) >= (30 if fmi == 2 else 70)
    slices = [_macho(s) for s in _macho_slices(data)]
    assert sorted(arch for arch, *_ in slices) == sorted(archs)
    for arch, dylibs, exported, undefined in slices:
        assert dylibs == [LIBSYSTEM], (arch, dylibs)
        missing = {f for f in functions if "_" + f not in exported}
        assert not missing, (arch, sorted(missing))
        outside = {n: lib for n, lib in undefined.items() if lib != LIBSYSTEM}
        assert not outside, (arch, outside)
        assert undefined, arch  # (the reader found the imports: the C library's, at least)


# ---- the source FMU -------------------------------------------------------------------------------

def _sources_only(name, folder, fmi=2):
    return _extract(name, folder, lambda m: m == "modelDescription.xml" or m.startswith("sources/"), fmi=fmi)


@pytest.mark.parametrize("name", FMUS)
def test_the_source_fmu_builds_with_the_system_compiler_from_its_own_files(name, tmp_path, linux_host, linux_runs):
    folder = _sources_only(name, tmp_path / "fmu")
    md = _description(folder)
    units = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    assert md.buildConfigurations[0].modelIdentifier == name and units
    out = folder / "binaries" / "linux64" / f"{name}.so"
    out.parent.mkdir(parents=True)
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    proc = subprocess.run([cc, "-shared", "-fPIC", "-O2", *units, "-o", str(out), "-lm"], cwd=folder / "sources",
                          capture_output=True, text=True, env=BARE_ENV)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rc, rows, err = run_c_host(linux_host, folder, name, *_experiment(md), outputs_of(name), md=md)
    assert rc == 0, err[-2000:]
    _assert_same_run(rows, linux_runs(name)[1], name, exact=EXACT)


@needs(shutil.which("cmake") is not None, "cmake (Debian: cmake; fmpy builds source FMUs with CMake)")
@pytest.mark.parametrize("fmi", [2, 3])
def test_fmpy_builds_the_source_fmu_and_simulates_it(tmp_path, fmi):
    """fmpy.build.build_platform_binary (CMake, fmpy's own FMI headers and flags) on the sources
    alone; simulate_fmu of the result gives the Python-hosted FMU's outputs."""
    from fmpy import simulate_fmu
    from fmpy.build import build_platform_binary

    name = "PogoStickSMA"
    folder = _sources_only(name, tmp_path / "fmu", fmi=fmi)
    (tmp_path / "build").mkdir()
    build_platform_binary(folder, build_dir=tmp_path / "build")
    assert (folder / "binaries" / ("linux64" if fmi == 2 else "x86_64-linux") / f"{name}.so").exists()
    stop, step = _experiment(_description(folder))
    got = simulate_fmu(str(folder), stop_time=stop, output_interval=step)
    ref = simulate_fmu(str(fmu_path(f"{'fmi3/' if fmi == 3 else ''}{name}")), stop_time=stop, output_interval=step)
    assert got["time"][-1] == ref["time"][-1] and got["n_events"][-1] == ref["n_events"][-1] > 10
    for column in ref.dtype.names:
        if EXACT:
            assert list(got[column]) == list(ref[column]), column
        else:
            assert max(abs(a - b) for a, b in zip(got[column], ref[column])) <= 1e-10, column


@pytest.mark.parametrize("name", FMUS)
def test_the_fmi3_build_description_validates_and_lists_every_c_file(name):
    """``sources/buildDescription.xml`` as the Reference-FMUs carry it: valid against the standard's
    schema (fmpy's read_build_description validates), one configuration of the model's identifier,
    its source files every ``.c`` of ``sources/`` and nothing else."""
    from fmpy.model_description import read_build_description

    fmu = fmu_path(f"native/fmi3/{name}")
    configs = read_build_description(str(fmu), validate=True)
    assert len(configs) == 1 and configs[0].modelIdentifier == name
    listed = [f for s in configs[0].sourceFileSets for f in s.sourceFiles]
    with zipfile.ZipFile(fmu) as z:
        on_disk = sorted(n.split("/", 1)[1] for n in z.namelist() if n.startswith("sources/") and n.endswith(".c"))
    assert sorted(listed) == on_disk and len(listed) == len(set(listed))


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("name", FMUS)
def test_each_platform_adds_less_than_300_kb_to_the_fmu(name, fmi):
    """Every binary of the native FMU, as stored (compressed) in its zip: under 300 kB."""
    with zipfile.ZipFile(fmu_path(f"native/{'fmi3/' if fmi == 3 else ''}{name}")) as z:
        sizes = {i.filename: i.compress_size for i in z.infolist() if i.filename.startswith("binaries/")}
    assert len(sizes) >= 4 and all(size < 300_000 for size in sizes.values()), sizes
