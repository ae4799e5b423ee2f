"""The sweep's files: the Parquet table's schema, its part files (one per finished chunk, for
--resume), the atomic writes, the per-run time series, and the checks of the output paths."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

from .spec import INTEGER_TYPES, SUMMARY_OUTPUTS, Settings, SweepError, recorded_outputs

def schema(md, names, settings: Settings):
    import pyarrow as pa

    vars_ = {v.name: v for v in md.modelVariables}
    typ = lambda n: pa.int64() if vars_[n].type in INTEGER_TYPES + ("Boolean", "Enumeration") else pa.float64()  # noqa: E731
    fields = [("run_id", pa.int64())] + [(n, typ(n)) for n in names]
    fields += [("status", pa.string()), ("message", pa.string()), ("wall_s", pa.float64())]
    for n in recorded_outputs(md, settings.outputs):
        if n in SUMMARY_OUTPUTS:
            fields.append((n, typ(n)))
        else:
            fields += [(f"{n}_{s}", typ(n)) for s in ("final", "min", "max")]
    if settings.events:
        fields += [("event_t", pa.list_(pa.float64())), ("event_name", pa.list_(pa.string())),
                   ("event_state", pa.list_(pa.map_(pa.string(), pa.float64())))]
    return pa.schema(fields)


def _write_atomic(table, path: Path, metadata=None):
    import pyarrow.parquet as pq

    if metadata:
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), **metadata})
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table, tmp)
    os.replace(tmp, path)


def _write_timeseries(folder: Path, run_id: int, res):
    import pyarrow as pa

    part = folder / f"run_id={run_id}"
    part.mkdir(parents=True, exist_ok=True)
    table = pa.table({n: res[n] for n in res.dtype.names})
    _write_atomic(table, part / "part-0.parquet")


def _parts_dir(out: Path) -> Path:
    return out.with_name(out.name + ".parts")


def _done_ids(parts: Path):
    import pyarrow.parquet as pq

    done = set()
    for f in sorted(parts.glob("chunk-*.parquet")):
        done.update(pq.read_table(f, columns=["run_id"]).column("run_id").to_pylist())
    return done


def check_output(out: Path, timeseries, overwrite: bool, resume: bool):
    """The output is a regular file in a writable folder (or does not exist yet); its ``.parts``
    folder and the timeseries folder are folders; an existing output is replaced only with
    ``--overwrite``, and only if it is a regular file: a device, a folder or a link to one is never
    replaced. Checked before any worker starts."""
    out = Path(out)
    if out.exists() or out.is_symlink():
        if not out.is_file() or out.is_symlink():
            kind = "a folder" if out.is_dir() else "a symbolic link" if out.is_symlink() else \
                "not a regular file (a device, a pipe or a socket)"
            raise SweepError(f"--out {out}: {kind}; give the path of a Parquet file to write (an existing output "
                             f"is replaced only if it is a regular file, with --overwrite)")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise SweepError(f"--out {out}: the folder {parent} does not exist")
    try:
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise SweepError(f"--out {out}: the folder {parent} cannot be written ({exc.strerror or exc})") from None
    parts = _parts_dir(out)
    if (parts.exists() or parts.is_symlink()) and (not parts.is_dir() or parts.is_symlink()):
        raise SweepError(f"{parts} exists and is not a folder of the sweep's parts: remove it or choose another --out")
    if timeseries:
        ts = Path(timeseries)
        if ts.exists() and (not ts.is_dir() or ts.is_symlink()):
            raise SweepError(f"--timeseries {ts}: exists and is not a folder")
        if ts.is_dir() and overwrite and not resume:
            foreign = [p.name for p in ts.iterdir() if not (p.is_dir() and p.name.startswith("run_id="))]
            if foreign:
                raise SweepError(f"--timeseries {ts}: holds {', '.join(sorted(foreign)[:3])}, which a sweep did not "
                                 f"write; --overwrite replaces only a sweep's own run_id=* folders")


def failed_runs(out: Path) -> int:
    """The runs of a written sweep whose status is not ``ok``."""
    import pyarrow.parquet as pq

    statuses = pq.read_table(out, columns=["status"]).column("status").to_pylist()
    return len(statuses) - statuses.count("ok")
