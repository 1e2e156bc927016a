"""The results store of a sweep: one directory, resumable, never half-written.

Layout of ``DIR``:

- ``sweep.json``: the base scenario's file and digest, the fixed overrides, the varied
  paths and seeds of the last invocation;
- ``runs/<run id>.json``: one file per finished run: its values, seed, row and full
  metrics (``metrics.json`` of ``sandbox run``), or the error of a failed run;
- ``results.csv`` (and ``results.parquet`` when pyarrow is installed): one row per run
  of the sweep, in grid-point then seed order, rebuilt from ``runs/`` at the end of
  every invocation (also an interrupted one).

Every file is written to a temporary name and renamed into place, so a killed sweep
leaves complete run files only; the next invocation computes the runs whose file is
missing. The digest is the SHA-256 of the base scenario document as canonical JSON
(sorted keys, so key order and comments do not matter) together with the fixed
overrides: a sweep into a ``DIR`` made from another base is refused, and so is one made
by another version of sandbox (``sweep.json`` and every run file record the version).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import os
from pathlib import Path
from typing import Any

from sandbox._about import __version__
from sandbox.study.spec import SweepError, SweepSpec, Task

#: Measured columns of ``results.csv``, after the run id, the varied paths and the seed.
MEASURED = (
    "status",
    "collisions.total",
    "collisions.vehicle_vehicle",
    "collisions.healthy",
    "min_distance",
    "converged",
    "settling_time",
    "effort",
    "deadlocks",
)
FORMAT = 1


def digest(base_doc: Any, fixed: tuple[str, ...]) -> str:
    """SHA-256 of the base document (canonical JSON) and the fixed overrides."""
    text = json.dumps(
        {"base": base_doc, "set": list(fixed)},
        sort_keys=True,
        separators=(",", ":"),
        default=str,
    )
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _finite(data: Any) -> Any:
    if isinstance(data, dict):
        return {k: _finite(v) for k, v in data.items()}
    if isinstance(data, list | tuple):
        return [_finite(v) for v in data]
    if isinstance(data, float):
        return data if math.isfinite(data) else None
    return data


def write_atomic(path: Path, text: str) -> None:
    """Write a text file whole or not at all (temporary name, then rename)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


class Store:
    """A sweep's results directory.

    Parameters
    ----------
    root : Path
        ``DIR``.
    """

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.runs = self.root / "runs"

    # ------------------------------------------------------------------ opening
    def open(self, spec: SweepSpec, base_digest: str) -> None:
        """Create ``DIR`` or check that it holds a sweep of the same base.

        Raises
        ------
        SweepError
            ``DIR`` holds a sweep of another base scenario or fixed overrides, or is a
            non-empty directory that holds no sweep.
        """
        meta = self.root / "sweep.json"
        if meta.is_file():
            try:
                old = json.loads(meta.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                raise SweepError(f"{meta}: unreadable sweep description") from None
            made_by = old.get("sandbox")
            if made_by is not None and made_by != __version__:
                raise SweepError(
                    f"{self.root}: its runs were computed by sandbox {made_by}, "
                    f"this is sandbox {__version__}; results of two versions are not "
                    "mixed: use a new --out directory"
                )
            if old.get("base_digest") != base_digest:
                raise SweepError(
                    f"{self.root}: holds a sweep of another base scenario or --set "
                    f"(was {old.get('base')} with set {old.get('set')}); the base "
                    "changed: use a new --out directory"
                )
        elif self.root.exists() and (
            not self.root.is_dir() or any(self.root.iterdir())
        ):
            raise SweepError(
                f"{self.root}: exists and holds no sweep (no sweep.json); refusing to "
                "write into it"
            )
        self.runs.mkdir(parents=True, exist_ok=True)
        doc = {
            "format": FORMAT,
            "sandbox": __version__,
            "base": str(spec.base),
            "base_digest": base_digest,
            "set": list(spec.fixed),
            "grid": {a.path: list(a.texts) for a in spec.grid},
            "zip": {a.path: list(a.texts) for a in spec.zipped},
            "seeds": [spec.seeds.start, spec.seeds.stop],
            "source": spec.source,
        }
        write_atomic(meta, json.dumps(doc, indent=2) + "\n")

    # ------------------------------------------------------------------ runs
    def path(self, run_id: str) -> Path:
        """The file of one run."""
        return self.runs / f"{run_id}.json"

    def done(self) -> dict[str, str]:
        """Status of every finished run, by run id."""
        out = {}
        for p in self.runs.glob("*.json"):
            try:
                out[p.stem] = json.loads(p.read_text(encoding="utf-8"))["row"]["status"]
            except (OSError, ValueError, KeyError):
                continue  # unreadable: computed again
        return out

    def put(self, task: Task, result: dict[str, Any]) -> None:
        """Store one finished run (atomically)."""
        doc = {
            "run_id": task.run_id,
            "sandbox": __version__,
            "values": dict(task.values),
            "seed": task.seed,
            **_finite(result),
        }
        write_atomic(self.path(task.run_id), json.dumps(doc, indent=1) + "\n")

    def get(self, run_id: str) -> dict[str, Any] | None:
        """One stored run, or None."""
        try:
            return json.loads(self.path(run_id).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None

    # ------------------------------------------------------------------ results
    def write_results(self, spec: SweepSpec, tasks: list[Task]) -> int:
        """Rebuild ``results.csv`` (and ``.parquet``) from the stored runs.

        Returns the number of rows (the runs of ``tasks`` that are stored).
        """
        header = ["run_id", *spec.paths, "seed", *MEASURED]
        rows = []
        for task in tasks:
            stored = self.get(task.run_id)
            if stored is None:
                continue
            row = stored["row"]
            rows.append(
                [
                    task.run_id,
                    *(t for _, t in task.values),
                    task.seed,
                    *(row.get(k) for k in MEASURED),
                ]
            )
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(header)
        for r in rows:
            writer.writerow([cell_text(v) for v in r])
        text = buf.getvalue()
        write_atomic(self.root / "results.csv", text)
        _write_parquet(self.root / "results.parquet", header, text, len(spec.paths))
        return len(rows)


def cell_text(value: Any) -> str:
    """A CSV cell: booleans true/false, floats at full precision, None empty."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def parquet_types(n_paths: int) -> list[Any]:
    """The pyarrow types of the columns of ``results.parquet`` (pyarrow imported)."""
    import pyarrow as pa

    return (
        [pa.string()] * (1 + n_paths)
        + [pa.int64(), pa.string(), pa.int64(), pa.int64(), pa.int64()]
        + [pa.float64(), pa.bool_(), pa.float64(), pa.float64(), pa.int64()]
    )


def _write_parquet(path: Path, header: list[str], text: str, n_paths: int) -> None:
    """``results.parquet`` with typed columns, when pyarrow is installed.

    The table is parsed from the text of ``results.csv`` by pyarrow's CSV reader
    (floats at full precision, ``true``/``false``, empty cells null): the same table
    as built from the rows' Python values, without the half second in which
    ``pyarrow.array`` imports pandas.
    """
    try:
        import pyarrow.csv as pc
        import pyarrow.parquet as pq
    except ImportError:
        return
    table = pc.read_csv(
        io.BytesIO(text.encode("utf-8")),
        read_options=pc.ReadOptions(use_threads=False),
        parse_options=pc.ParseOptions(newlines_in_values=True),
        convert_options=pc.ConvertOptions(
            column_types=dict(zip(header, parquet_types(n_paths), strict=True)),
            null_values=[""],
            true_values=["true"],
            false_values=["false"],
            strings_can_be_null=False,
            quoted_strings_can_be_null=False,
        ),
    ).combine_chunks()
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        pq.write_table(table, tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def read_results(root: Path) -> tuple[list[str], list[dict[str, str]]]:
    """The header and rows of ``DIR/results.csv``."""
    path = Path(root) / "results.csv"
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            reader = csv.DictReader(fh)
            rows = list(reader)
            return list(reader.fieldnames or []), rows
    except OSError as exc:
        raise SweepError(f"{path}: cannot read ({exc.strerror or exc})") from None


def varied_paths(root: Path) -> list[str]:
    """The varied paths of the sweep in ``DIR`` (from ``sweep.json``)."""
    meta = json.loads((Path(root) / "sweep.json").read_text(encoding="utf-8"))
    return [*meta.get("grid", {}), *meta.get("zip", {})]


def varied_axes(root: Path) -> list[tuple[str, ...]]:
    """The sweep's axes: each grid path alone, then the zipped paths as one axis."""
    meta = json.loads((Path(root) / "sweep.json").read_text(encoding="utf-8"))
    axes = [(p,) for p in meta.get("grid", {})]
    if meta.get("zip"):
        axes.append(tuple(meta["zip"]))
    return axes
