"""The segmented mirror (docs/segmented-mirror.md) as a user runs it: the example's model files
copied into a temporary folder and exported by ``pogofmu export``; each model against an
independent reference written here (scipy for the actuator and the controller, numpy's
least squares for the reconstructor); ``pogofmu mirror`` packages checked by ``pogofmu ssp
check``, and a 1-ring mirror run by ``pogofmu ssp run``.
"""
from __future__ import annotations

import math
import re
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

from support import parse_event_log, run_pogofmu

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "segmented_mirror"


def pogofmu(*args, cwd):
    return run_pogofmu(*args, cwd=cwd, timeout=900)


@pytest.fixture(scope="module")
def user(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mirror_user")
    for f in EXAMPLE.glob("*.py"):
        shutil.copy(f, folder / f.name)
    for args in (("mirror_actuator.py", "segment_controller.py"), ("reconstructor.py", "--model", "Reconstructor_R1")):
        proc = pogofmu("export", *args, "--out", "out", cwd=folder)
        assert proc.returncode == 0, proc.stderr
        assert "Traceback" not in proc.stdout + proc.stderr
    return folder


def fmu(folder, name, backend="python", fmi=2):
    out = folder / "out" / ("native" if backend == "native" else "")
    return out / ("fmi3" if fmi == 3 else "") / f"{name}.fmu"


def simulate(path, stop, step, start=None, **kw):
    from fmpy import simulate_fmu

    messages = []
    res = simulate_fmu(str(path), stop_time=stop, output_interval=step, debug_logging=True,
                       start_values={"log_events": 1, "rel_tol": 1e-10, **(start or {})},
                       logger=lambda *a: messages.append((a[-3], a[-2].decode() if a[-2] else "", a[-1].decode())),
                       **kw)
    assert res["time"][-1] == pytest.approx(stop)
    return res, parse_event_log(messages)


def hybrid_solve(flow, events, x0, q0, stop, rtol=1e-12, atol=1e-15):
    """scipy Radau through the events ``(name, direction, guard(x, q), active(q), jump(x, q))``."""
    from scipy.integrate import solve_ivp

    t, x, q, out = 0.0, list(x0), dict(q0), []
    while t < stop:
        act = [ev for ev in events if ev[3](q)]
        fns = []
        for _, direction, guard, _, _ in act:
            fn = (lambda g, qq: lambda tt, xx: g(xx, qq))(guard, dict(q))
            fn.terminal, fn.direction = True, direction
            fns.append(fn)
        sol = solve_ivp(lambda tt, xx: flow(tt, xx, q), (t, stop), x, method="Radau", rtol=rtol, atol=atol,
                        events=fns)
        hits = [(sol.t_events[k][0], k) for k in range(len(fns)) if len(sol.t_events[k]) and sol.t_events[k][0] > t]
        if not hits:
            return out
        te, k = min(hits)
        out.append((act[k][0], te))
        x, q = act[k][4](list(sol.y_events[k][0]), q)
        t = te
    return out


def test_actuator_stop_contacts_and_releases_match_an_independent_stiff_solve(user):
    """The gust pushes the free actuator (F = 0) into its upper stop, where it bounces; every
    contact and release within 1e-8 s of scipy Radau (rtol 1e-12) on the equations written here,
    in FMI 2.0 and FMI 3.0 co-simulation; the native FMUs give the Python-hosted ones' bits."""
    m, k, c, km, beta, zs = 83.0, 1.2e4, 50.0, 2.0e3, 200.0, 2.0e-3
    K, cr, d0 = 1.0e8, 0.5, 0.01
    lam = 1.5 * (1 - cr) * K / d0
    Aw, tg, Tg = 60.0, 0.1, 0.5

    def hc(delta, rate):
        return (K + lam * rate) * max(delta, 0.0)

    def flow(t, x, q):
        z, zd, a = x
        Fw = 0.5 * Aw * (1 - math.cos(2 * math.pi * (t - tg) / Tg)) if tg < t < tg + Tg else 0.0
        Fs = -hc(z - zs, zd) if q["s"] == 1 else (hc(-zs - z, -zd) if q["s"] == -1 else 0.0)
        return [zd, (Fw - k * z - c * zd - km / (1 + beta * abs(a)) * z + Fs) / m, z]

    up, lo = (lambda x, q: x[0] - zs), (lambda x, q: x[0] + zs)
    events = [("upper_contact", 1, up, lambda q: q["s"] == 0, lambda x, q: (x, {"s": 1})),
              ("upper_release", -1, up, lambda q: q["s"] == 1, lambda x, q: (x, {"s": 0})),
              ("lower_contact", -1, lo, lambda q: q["s"] == 0, lambda x, q: (x, {"s": -1})),
              ("lower_release", 1, lo, lambda q: q["s"] == -1, lambda x, q: (x, {"s": 0}))]
    ref = hybrid_solve(flow, events, [0.0, 0.0, 0.0], {"s": 0}, 1.0)
    assert len(ref) >= 6 and ref[0][0] == "upper_contact"
    for fmi, kw in ((2, {}), (3, dict(fmi_type="CoSimulation", early_return_allowed=True, use_event_mode=True))):
        py, evs = simulate(fmu(user, "MirrorActuator", "python", fmi), 1.0, 1e-3, **kw)
        nat, evs_n = simulate(fmu(user, "MirrorActuator", "native", fmi), 1.0, 1e-3, **kw)
        for col in py.dtype.names:
            assert np.array_equal(py[col], nat[col]), (fmi, col)
        assert [e["time"] for e in evs] == [e["time"] for e in evs_n]
        got = [(e["name"], e["time"]) for e in evs]
        assert [n for n, _ in got] == [n for n, _ in ref], fmi
        assert max(abs(a[1] - b[1]) for a, b in zip(got, ref)) < 1e-8, fmi
        on = py["mode"] == 1
        assert on.any() and (py["F_stop"][on] <= 0).all()  # the upper stop pushes down


def test_controller_enters_and_leaves_saturation_at_scipy_times_in_fmi3_model_exchange(user):
    """A derivative kick (the filter starting 2 mm below the piston) holds the clip at -F_max;
    as the filter settles the loop leaves it and the error drives it into +F_max: both kinks are
    events of FMI 3.0 model exchange, within 1e-6 s of scipy on the PID written here."""
    Kp, Ki, Kd, Tf, Tt, Fmax = 3.3e5, 4.0e6, 7.0e3, 0.02, 0.04, 25.0
    r, z, w0 = 1e-3, 0.0, -2e-3

    def Fu(x):
        return Kp * (r - z) + Ki * x[0] - Kd * (z - x[1]) / Tf

    def flow(t, x, q):
        F = min(max(Fu(x), -Fmax), Fmax)
        return [(r - z) + (F - Fu(x)) / (Ki * Tt), (z - x[1]) / Tf]

    hi, lo = (lambda x, q: Fu(x) - Fmax), (lambda x, q: Fu(x) + Fmax)
    same = lambda x, q: (x, q)  # noqa: E731
    events = [("saturate_high", 1, hi, lambda q: True, same), ("leave_high", -1, hi, lambda q: True, same),
              ("saturate_low", -1, lo, lambda q: True, same), ("leave_low", 1, lo, lambda q: True, same)]
    ref = hybrid_solve(flow, events, [0.0, w0], {}, 0.2, rtol=1e-11, atol=1e-14)
    assert [n for n, _ in ref] == ["leave_low", "saturate_high"]
    start = {"T_f": Tf, "z_0": w0, "r": r, "z": z}
    for backend in ("python", "native"):
        res, evs = simulate(fmu(user, "SegmentController", backend, 3), 0.2, 1e-4, start, fmi_type="ModelExchange",
                            solver="CVode", relative_tolerance=1e-10)
        got = [(e["name"], e["time"]) for e in evs]
        assert [n for n, _ in got] == [n for n, _ in ref], backend
        assert max(abs(a[1] - b[1]) for a, b in zip(got, ref)) < 1e-6, backend
        assert res["sat"][0] == -1 and res["sat"][-1] == 1
        assert abs(res["F"][-1] - Fmax) < 1e-12


def test_reconstructor_commands_are_the_least_squares_relative_pistons(user):
    """r_i = z_target - G z_rel_i, z_rel the minimum-norm least-squares solution of D z_rel = D z
    (numpy's lstsq) for the 12 edge sensors of the 1-ring grid: the centre borders all six, each
    ring segment its two ring neighbours."""
    edges = [(0, i) for i in range(1, 7)] + [(i, i % 6 + 1) for i in range(1, 7)]
    D = np.zeros((len(edges), 7))
    for e, (i, j) in enumerate(edges):
        D[e, i], D[e, j] = -1.0, 1.0
    rng = np.random.default_rng(30)
    zt, G = 3e-4, 0.8
    for trial in range(3):
        z = rng.uniform(-1e-3, 1e-3, 7)
        rel = np.linalg.lstsq(D, D @ z, rcond=None)[0]
        start = {"z_target": zt, "G": G, **{f"z[{i + 1}]": z[i] for i in range(7)}}  # FMI 2.0: scalars
        rows = []
        for backend in ("python", "native"):
            res, _ = simulate(fmu(user, "Reconstructor_R1", backend), 0.002, 1e-3, start)
            rows.append(res)
            got = np.array([res[f"r[{i + 1}]"][-1] for i in range(7)])
            assert np.max(np.abs(got - (zt - G * rel))) < 1e-15, backend
            assert res["piston_rms"][-1] == pytest.approx(np.sqrt(np.mean(rel ** 2)), rel=1e-12)
            # FMI 3.0: the arrays z and r, one value reference each, the same bits
            assert fmi3_commands(fmu(user, "Reconstructor_R1", backend, 3), zt, G, z) == list(got), backend
        for col in rows[0].dtype.names:
            assert np.array_equal(rows[0][col], rows[1][col]), col


def fmi3_commands(path, zt, G, z):
    """The FMI 3.0 Reconstructor's ``r`` for the pistons ``z``: ``z`` and ``r`` are arrays of 7
    (``<Dimension start="7"/>``), set and got with one value reference and nValues = 7."""
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(str(path))
    v = {var.name: var for var in md.modelVariables}
    assert [int(d.start) for d in v["z"].dimensions] == [7] and [int(d.start) for d in v["r"].dimensions] == [7]
    f = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="rec")
    f.instantiate()
    f.enterInitializationMode()
    f.setFloat64([v["z_target"].valueReference, v["G"].valueReference], [zt, G])
    f.setFloat64([v["z"].valueReference], [float(e) for e in z])
    f.exitInitializationMode()
    f.doStep(0.0, 1e-3)
    out = f.getFloat64([v["r"].valueReference], nValues=7)
    f.terminate()
    f.freeInstance()
    return out


def test_mirror_packages_of_one_ring_have_15_components_and_pass_ssp_check(tmp_path):
    for fmi, version in (("2", "1.0"), ("3", "2.0")):
        out = tmp_path / f"mirror{fmi}.ssp"
        proc = pogofmu("mirror", "--rings", "1", "--fmi", fmi, "--out", out, cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        assert "15 FMUs" in proc.stdout
        check = pogofmu("ssp", "check", out, cwd=tmp_path)
        assert check.returncode == 0, check.stderr
        listed = check.stdout.split("components [")[1].split("]")[0].split(", ")
        assert len(listed) == 15 and sum(c.startswith("'Actuator_") for c in listed) == 7
        assert update_order(out, tmp_path / f"unpacked{fmi}") == \
            [f"Actuator_{i}" for i in range(1, 8)] + ["Reconstructor"] + [f"Controller_{i}" for i in range(1, 8)]
        with zipfile.ZipFile(out) as z:
            ssd = z.read("SystemStructure.ssd").decode()
            assert f'version="{version}"' in ssd
            if fmi == "3":  # the Reconstructor's arrays, each segment connected to its element
                from lxml import etree

                schema = etree.XMLSchema(file=str(EXAMPLE.parents[1] / "ssp" / "schema" / "ssp-2.0"
                                                  / "SystemStructureDescription.xsd"))
                assert schema.validate(etree.fromstring(ssd.encode())), schema.error_log
                assert ssd.count('<ssc:Dimension size="7"/>') == 2
                assert 'startElement="Actuator_4" startConnector="z" endElement="Reconstructor" ' \
                    'endConnector="z" endIndices="4"' in ssd
                assert 'startConnector="r" startIndices="4" endElement="Controller_4" endConnector="r"' in ssd
            else:
                assert 'endConnector="z[4]"' in ssd and 'startConnector="r[4]"' in ssd
            with zipfile.ZipFile(z.open("resources/SegmentController.fmu")) as f:
                assert f'fmiVersion="{fmi}.0"' in f.read("modelDescription.xml").decode()
            # one parameter set per component and nothing else: each component bound to its own set,
            # no part of another component's set (those made 2 N^2 files: 442 741 at 12 rings)
            sets = sorted(n for n in z.namelist() if n.endswith(".ssv"))
            assert len(sets) == 15 and "resources/reconstructor.ssv" in sets, sets
            assert set(re.findall(r'ParameterBinding source="([^"]+)"', ssd)) == set(sets)


def update_order(ssp, folder):
    """The master's update order of a package: the Reconstructor's inputs feed its outputs directly,
    element by element in FMI 2.0 and as the arrays z -> r in FMI 3.0, so it comes after every
    actuator and before every controller."""
    from pogofmu.ssp.package import read_ssd, unpack
    from pogofmu.ssp.validate import validate

    system = read_ssd(unpack(ssp, folder))
    validate(system)
    return system.update_order()


@pytest.mark.parametrize("args", [("--rings", "0", "--out", "m.ssp"), ("--rings", "1", "--out", "m.zip")])
def test_a_wrong_mirror_command_is_one_line_without_traceback(tmp_path, args):
    proc = pogofmu("mirror", *args, cwd=tmp_path)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_one_ring_mirror_phases_after_its_gust_with_actuators_on_their_stops(tmp_path):
    """Every piston ends within 1 um of the 0.5 mm target at 1.5 s, the relative pistons within
    0.1 um rms, after the gust (0.3-0.7 s) held segments on their upper and lower stops.  The
    loops' slowest mode decays by about 10x per 0.2 s (the integral, T_i = K_p/K_i = 0.08 s, with
    the reconstructor's gain), so 0.8 s after a 2.5 mm excursion leaves well under 1 um; a loop
    that did not phase, or an event handled wrong, would be off by tens of um."""
    ssp = tmp_path / "m.ssp"
    assert pogofmu("ssp", "mirror", "--rings", "1", "--out", ssp, cwd=tmp_path).returncode == 0  # (the old command line)
    proc = pogofmu("ssp", "run", ssp, "--step", "1e-3", "--out", "run", "--quiet", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    data = np.genfromtxt(tmp_path / "run" / "default.csv", delimiter=",", names=True, deletechars="")
    assert data["time"][-1] == pytest.approx(1.5)
    modes = np.array([data[f"Actuator_{i}.mode"] for i in range(1, 8)])
    assert (modes == 1).any() and (modes == -1).any()
    assert (modes[:, -1] == 0).all()
    final = np.array([data[f"Actuator_{i}.z"][-1] for i in range(1, 8)])
    assert np.max(np.abs(final - 5e-4)) < 1e-6
    assert data["Reconstructor.piston_rms"][-1] < 1e-7
    assert (data["event"] != 0).any()  # the stops' contacts are synchronized events of the master


def test_controllers_whose_saturation_events_undo_each_other_end_in_one_line_not_a_hang(tmp_path):
    """With the controllers' saturation events on, two components switched each other back and forth
    at one instant (t = 0.0417 s): the master wrote event rows without end (4.3 GB of CSV). Now
    it stops with an event storm naming the instant, exit status 1, one line."""
    ssp = tmp_path / "m.ssp"
    assert pogofmu("ssp", "mirror", "--rings", "1", "--out", ssp, cwd=tmp_path).returncode == 0  # (the old command line)
    edited = tmp_path / "storm.ssp"
    with zipfile.ZipFile(ssp) as src, zipfile.ZipFile(edited, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename.endswith(".ssv"):
                off = '<ssv:Parameter name="locate_saturation"><ssv:Integer value="0"/>'
                data = data.decode().replace(off, off.replace('"0"', '"1"')).encode()
            dst.writestr(item, data)
    proc = run_pogofmu("ssp", "run", edited, "--step", "1e-3", "--stop-time", "0.1", "--out", tmp_path / "run",
                       "--quiet", cwd=tmp_path, timeout=600)
    assert proc.returncode == 1 and "event storm across the system" in proc.stderr, proc.stderr[-1500:]
    assert "Traceback" not in proc.stderr and proc.stderr.startswith("error: event storm")  # (then where the rows are)
    assert sum(f.stat().st_size for f in (tmp_path / "run").glob("*")) < 50e6
