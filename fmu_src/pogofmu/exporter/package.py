"""Packing an FMU: the deterministic zip, its ``documentation/`` and fmpy's validation."""
from __future__ import annotations

import contextlib
import html
import os
import zipfile
from pathlib import Path

from .errors import BuildError, OutputError

ZIP_DATE = (1980, 1, 1, 0, 0, 0)


@contextlib.contextmanager
def output_file(out: Path):
    """Yields a temporary path beside ``out`` to write ``out`` into; when the block ends, it becomes
    ``out`` at once (os.replace) — on any failure (disk full, no permission, Ctrl-C, a refusal of the
    block) it is removed and ``out`` is left as it was: no temporary file and no half-written ``out``
    stays behind. An OSError is an :class:`OutputError` naming ``out`` and the reason."""
    tmp = out.with_name(f"{out.name}.{os.getpid()}.tmp")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        yield tmp
        os.replace(tmp, out)
    except OSError as exc:
        raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from None
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def write_zip(out: Path, members, what: str = ""):
    """members: (arcname, bytes, executable); deterministic (fixed dates, sorted): with
    SOURCE_DATE_EPOCH set, the same sources give the same FMU bytes. ``what``: an FMU, validated
    (:func:`validate`) before it takes its name."""
    with output_file(out) as tmp:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            for name, data, executable in sorted(members, key=lambda m: m[0]):
                info = zipfile.ZipInfo(name, ZIP_DATE)
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = (0o755 if executable else 0o644) << 16
                z.writestr(info, data)
        if what:
            validate(tmp, what, out.name)


def validate(fmu: Path, what: str, name: str = "") -> None:
    from fmpy.validation import validate_fmu

    problems = validate_fmu(str(fmu))
    if problems:
        raise BuildError(f"{name or fmu.name} ({what}): fmpy validation failed: " + "; ".join(problems))


def _rows(variables):
    return [(p.name, p.unit, p.description) for p in variables]


def documentation(source, backend: str, fmi_version: int, platforms) -> list:
    """``documentation/index.html`` (what the FMU is, its variables, what it needs on the target)
    and, for a model with third-party requirements, ``documentation/requirements.txt``."""
    from .description import project_version

    model = source.model
    esc = html.escape
    needs = ("nothing but libc and libm (no Python at run time)" if backend == "native" else
             "a CPython 3.10 or newer shared library on the target (the launcher finds it)")
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{esc(model.name)}</title></head><body>",
             f"<h1>{esc(model.name)}</h1><p>{esc(model.description)}</p>",
             f"<p>FMI {fmi_version}.0, exported by pogofmu {esc(project_version())} "
             f"({'native: C generated from the Python model' if backend == 'native' else 'Python-hosted'}); "
             f"binaries: {esc(', '.join(platforms))}. Needs {esc(needs)}.</p>",
             f"<p>Model file: {esc(source.origin_name)}.</p>"]
    if source.requirements:
        parts.append("<h2>Requirements</h2><p>The model imports these third-party modules: the Python that runs "
                     "the FMU must have them installed:</p><ul>"
                     + "".join(f"<li>{esc(r)}</li>" for r in source.requirements) + "</ul>")
    for title, rows in (("Parameters", _rows(model.parameters)), ("Inputs", _rows(model.inputs)),
                        ("Outputs", _rows(model.outputs)), ("States", _rows(model.states))):
        if rows:
            parts.append(f"<h2>{title}</h2><table><tr><th>name</th><th>unit</th><th>description</th></tr>"
                         + "".join(f"<tr><td>{esc(n)}</td><td>{esc(u)}</td><td>{esc(d)}</td></tr>" for n, u, d in rows)
                         + "</table>")
    if model.events:
        parts.append("<h2>Events</h2><ol>" + "".join(
            f"<li>{esc(ev.name)} ({'falling' if ev.direction < 0 else 'rising'})</li>" for ev in model.events)
            + "</ol><p>Events listed first win when several happen at one instant.</p>")
    parts.append("<p>The solver settings (rel_tol, abs_tol, method, ...) are parameters of every pogofmu FMU.</p>"
                 "</body></html>\n")
    members = [("documentation/index.html", "".join(parts).encode(), False)]
    if source.requirements:
        members.append(("documentation/requirements.txt", ("\n".join(source.requirements) + "\n").encode(), False))
    return members
