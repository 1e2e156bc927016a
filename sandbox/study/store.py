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
missing. A file that cannot be written is named in the error by its own path, never
the temporary one's.

Nothing in the store is trusted on its word: a run file counts for a run only if its
name, run id, values and seed are that run's and its ``base_digest`` is the sweep's
(otherwise it is named in a warning and computed again), and ``sweep table`` and
``sweep plot`` rebuild the table from the run files whenever ``results.csv`` differs
from them (a file cut short, a wrong header, a row pasted in). One sweep at a time
writes into a store: a second one is refused while the first holds ``DIR/.lock``.

The digest is the SHA-256 of the base scenario document as canonical JSON
(sorted keys, so key order and comments do not matter) together with the fixed
overrides: a sweep into a ``DIR`` made from another base is refused, and so is one made
by another version of sandbox (``sweep.json`` and every run file record the version).
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
import math
import os
import stat
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from sandbox._about import __version__
from sandbox.errors import OutputError
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
#: Statuses a stored row may have.
STATUSES = ("ok", "diverged", "invalid", "error")
#: A run file larger than this is not read (one holds the metrics of one run).
MAX_RUN_BYTES = 64_000_000
#: The lock file of a store, held while a sweep writes into it.
LOCK = ".lock"


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
    """Write a text file whole or not at all (temporary name, then rename).

    Raises
    ------
    OutputError
        It cannot be written (read-only directory, full disk, ...): the message names
        ``path``, not the temporary file.
    """
    replace_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def replace_atomic(path: Path, write: Callable[[Path], Any]) -> None:
    """Have ``write(tmp)`` write a temporary file, then rename it to ``path``.

    A hidden temporary name beside ``path`` (``.NAME.PID.tmp``), removed on any
    failure; an ``OSError`` becomes an :class:`~sandbox.errors.OutputError` that names
    ``path`` and the reason (``Permission denied``, ``No space left on device``).
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        if os.path.lexists(tmp):  # a stale (or planted) one is never written through
            os.unlink(tmp)
        write(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        reason = exc.strerror or type(exc).__name__
        raise OutputError(f"{path}: cannot write ({reason})") from None
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        raise


def read_meta(root: Path) -> dict[str, Any]:
    """``DIR/sweep.json``, checked to be the description ``sandbox sweep`` writes.

    Raises
    ------
    SweepError
        One line naming the file: missing, unreadable, or not such a description.
    """
    meta = Path(root) / "sweep.json"
    try:
        data = _read_bounded(meta, 10_000_000)
        doc = json.loads(data.decode("utf-8"))
    except FileNotFoundError:
        raise SweepError(f"{meta}: no such file (not a sweep directory)") from None
    except OSError as exc:
        raise SweepError(f"{meta}: cannot read ({exc.strerror or exc})") from None
    except (ValueError, RecursionError):
        raise SweepError(
            f"{meta}: not JSON (expected the sweep.json that sandbox sweep writes)"
        ) from None
    problem = _meta_problem(doc)
    if problem:
        raise SweepError(
            f"{meta}: {problem} (expected the sweep.json that sandbox sweep writes)"
        )
    return doc


def _meta_problem(doc: Any) -> str | None:
    if not isinstance(doc, dict):
        return f"not a sweep description ({type(doc).__name__})"
    for key in ("grid", "zip"):
        axes = doc.get(key, {})
        if not isinstance(axes, dict) or not all(
            isinstance(v, list) and all(isinstance(t, str) for t in v)
            for v in axes.values()
        ):
            return f"{key}: not a mapping of paths to lists of values"
    seeds = doc.get("seeds", [0, 1])
    if not (
        isinstance(seeds, list)
        and len(seeds) == 2
        and all(isinstance(x, int) and not isinstance(x, bool) for x in seeds)
    ):
        return "seeds: not [first, end]"
    for key in ("base_digest", "sandbox"):
        if key in doc and not isinstance(doc[key], str):
            return f"{key}: not a string"
    return None


def _read_bounded(path: Path, limit: int) -> bytes:
    """A regular file's bytes, if it has at most ``limit`` of them."""
    st = os.stat(path)
    if stat.S_ISDIR(st.st_mode):
        raise IsADirectoryError(21, "Is a directory")
    if not stat.S_ISREG(st.st_mode):
        raise OSError(0, "not a regular file")
    if st.st_size > limit:
        raise OSError(0, f"larger than {limit:,} bytes")
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):  # replaced meanwhile
            raise OSError(0, "not a regular file")
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise OSError(0, f"larger than {limit:,} bytes")
    return data


def _row_problem(row: Any) -> str | None:
    """What is wrong with a stored row (None: a row of the measured columns)."""
    if not isinstance(row, dict):
        return "row: not a mapping of the measured columns"
    if row.get("status") not in STATUSES:
        return f"row.status: not one of {', '.join(STATUSES)}"
    for key in MEASURED[1:]:
        value = row.get(key)
        if value is not None and not isinstance(value, bool | int | float):
            return f"row.{key}: not a number"
    return None


def run_problem(
    path: Path, doc: Any, task: Task | None, base_digest: str | None
) -> str | None:
    """Why a run file's document is not a run of this sweep (None: it is).

    Checked: its name is its run id, it records the values and seed of ``task`` (the
    run of that id) and the sweep's ``base_digest``, and its row holds the measured
    columns.
    """
    if not isinstance(doc, dict):
        return f"not a run file ({type(doc).__name__})"
    if doc.get("run_id") != path.stem:
        return f"run_id: {str(doc.get('run_id'))[:40]!r} is not its name"
    if base_digest is not None and doc.get("base_digest") != base_digest:
        return "base_digest: not this sweep's base scenario and --set"
    if task is not None and (
        doc.get("values") != dict(task.values) or doc.get("seed") != task.seed
    ):
        return "values, seed: not those of the run of this id"
    return _row_problem(doc.get("row"))


def read_run(path: Path) -> Any:
    """A run file's JSON document (``OSError`` or ``ValueError`` if unreadable)."""
    return json.loads(_read_bounded(path, MAX_RUN_BYTES).decode("utf-8"))


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
        self.digest: str | None = None
        #: One line for every run file that was not taken (named, with why).
        self.rejected: list[str] = []
        self._lock: Any = None
        #: What this store wrote of each run it stored (run id, digest, values, seed,
        #: row): read back as it was written, under the lock, without the file.
        self._written: dict[str, dict[str, Any]] = {}

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
        self.digest = base_digest
        if meta.is_file():
            old = read_meta(self.root)
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
            not self.root.is_dir() or any(p.name != LOCK for p in self.root.iterdir())
        ):
            raise SweepError(
                f"{self.root}: exists and holds no sweep (no sweep.json); refusing to "
                "write into it"
            )
        try:
            self.root.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(
                f"{self.root}: cannot create ({exc.strerror or exc})"
            ) from None
        self.lock()
        try:
            self.runs.mkdir(exist_ok=True)
        except OSError as exc:
            raise OutputError(
                f"{self.runs}: cannot create ({exc.strerror or exc})"
            ) from None
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

    def lock(self) -> None:
        """Hold ``DIR/.lock`` until :meth:`close`: one sweep at a time writes here.

        Raises
        ------
        SweepError
            Another process holds it (a sweep into the same ``DIR`` under way).
        """
        try:
            import fcntl
        except ImportError:  # not on POSIX: no lock
            return
        path = self.root / LOCK
        flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
        try:  # never through a link, never a device or a pipe
            fd = os.open(path, flags | getattr(os, "O_NONBLOCK", 0), 0o644)
        except OSError as exc:
            raise OutputError(f"{path}: cannot write ({exc.strerror or exc})") from None
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            raise OutputError(f"{path}: cannot write (not a regular file)")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.read(fd, 32).decode("ascii", "replace").strip()
            os.close(fd)
            who = f" (process {holder})" if holder.isdigit() else ""
            raise SweepError(
                f"{self.root}: another sandbox sweep is writing into it{who}; wait "
                "for it to end, or use another --out"
            ) from None
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
        self._lock = fd

    def close(self) -> None:
        """Let go of the lock (another sweep may write into ``DIR`` again)."""
        if self._lock is not None:
            with contextlib.suppress(OSError):
                os.close(self._lock)
            self._lock = None

    # ------------------------------------------------------------------ runs
    def path(self, run_id: str) -> Path:
        """The file of one run."""
        return self.runs / f"{run_id}.json"

    def done(self, tasks: Iterable[Task] | None = None) -> dict[str, str]:
        """Status of every finished run of ``tasks``, by run id.

        A run file that is not the run's (see :func:`run_problem`) does not count; it
        is named in :attr:`rejected`, and the run is computed again. Without
        ``tasks``, every readable run file with a row counts (unchecked).
        """
        out = {}
        if tasks is None:
            for p in self.runs.glob("*.json"):
                doc = self.get(p.stem)
                if doc is not None and _row_problem(doc.get("row")) is None:
                    out[p.stem] = doc["row"]["status"]
            return out
        for task in tasks:
            doc = self.verified(task)
            if doc is not None:
                out[task.run_id] = doc["row"]["status"]
        return out

    def verified(self, task: Task) -> dict[str, Any] | None:
        """The stored run of ``task`` if it is one (else None, noted when wrong)."""
        path = self.path(task.run_id)
        doc = self._written.get(task.run_id)
        if doc is not None and run_problem(path, doc, task, self.digest) is None:
            return doc
        try:
            doc = read_run(path)
        except FileNotFoundError:
            return None
        except (OSError, ValueError, RecursionError) as exc:
            why = exc.strerror if isinstance(exc, OSError) and exc.strerror else None
            self.rejected.append(f"{path}: {why or 'not JSON'}; computed again")
            return None
        problem = run_problem(path, doc, task, self.digest)
        if problem is not None:
            self.rejected.append(f"{path}: {problem}; computed again")
            return None
        return doc

    def put(self, task: Task, result: dict[str, Any]) -> None:
        """Store one finished run (atomically)."""
        doc = {
            "run_id": task.run_id,
            "sandbox": __version__,
            "base_digest": self.digest,
            "values": dict(task.values),
            "seed": task.seed,
            **_finite(result),
        }
        write_atomic(self.path(task.run_id), json.dumps(doc, indent=1) + "\n")
        kept = {k: doc[k] for k in ("run_id", "base_digest", "values", "seed", "row")}
        self._written[task.run_id] = json.loads(json.dumps(kept))  # as read back

    def get(self, run_id: str) -> dict[str, Any] | None:
        """One stored run, or None (unchecked: see :meth:`verified`)."""
        try:
            doc = read_run(self.path(run_id))
        except (OSError, ValueError, RecursionError):
            return None
        return doc if isinstance(doc, dict) else None

    # ------------------------------------------------------------------ results
    def write_results(self, spec: SweepSpec, tasks: Iterable[Task]) -> int:
        """Rebuild ``results.csv`` (and ``.parquet``) from the stored runs.

        Returns the number of rows (the runs of ``tasks`` that are stored, checked as
        :meth:`verified` checks them).
        """
        header = ["run_id", *spec.paths, "seed", *MEASURED]
        rows = []
        rejected = len(self.rejected)
        for task in tasks:
            stored = self.verified(task)
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
        del self.rejected[rejected:]  # named once, when the runs were counted
        text = table_text(header, rows)
        write_atomic(self.root / "results.csv", text)
        _write_parquet(self.root / "results.parquet", header, text, len(spec.paths))
        return len(rows)


def table_text(header: list[str], rows: list[list[Any]]) -> str:
    """The text of ``results.csv``: the header, then one line per row."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for r in rows:
        writer.writerow([cell_text(v) for v in r])
    return buf.getvalue()


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
    replace_atomic(path, lambda tmp: pq.write_table(table, tmp))


def rebuilt_text(root: Path, meta: dict[str, Any]) -> tuple[str, list[str]]:
    """The text ``results.csv`` should have, from the run files; and the rejected.

    The rows are the run files of the sweep ``sweep.json`` describes (their values
    among its grid and zip values, their seed in its seeds, their name their run id,
    their ``base_digest`` its own), in grid-point then seed order, as
    :meth:`Store.write_results` writes them.
    """
    root = Path(root)
    grid = {p: {t: i for i, t in enumerate(v)} for p, v in meta.get("grid", {}).items()}
    zips = meta.get("zip", {})
    zip_paths = list(zips)
    zip_rows: dict[tuple[str, ...], int] = {}
    if zip_paths:
        for i, row in enumerate(zip(*zips.values(), strict=False)):
            zip_rows.setdefault(tuple(row), i)
    first, end = meta.get("seeds", [0, 1])
    paths = [*grid, *zip_paths]
    digest_ = meta.get("base_digest")
    found: dict[tuple[Any, ...], list[Any]] = {}
    rejected = []
    for path in sorted((root / "runs").glob("*.json")):
        try:
            doc = read_run(path)
        except (OSError, ValueError, RecursionError):
            rejected.append(f"{path}: not a readable run file; left out")
            continue
        problem = run_problem(path, doc, None, digest_)
        if problem is None:
            values, seed = doc.get("values"), doc.get("seed")
            if not isinstance(values, dict) or list(values) != paths:
                continue  # a run of another grid of this store
            if not (isinstance(seed, int) and first <= seed < end):
                continue
            where = [grid[p].get(values[p]) for p in grid]
            z = zip_rows.get(tuple(values[p] for p in zip_paths), -1)
            if None in where or (zip_paths and z < 0):
                continue
            key = (*where, z, seed)
            if key in found:
                problem = "the values and seed of another run file"
            else:
                row = doc["row"]
                found[key] = [
                    doc["run_id"],
                    *(values[p] for p in paths),
                    seed,
                    *(row.get(k) for k in MEASURED),
                ]
        if problem is not None:
            rejected.append(f"{path}: {problem}; left out")
    rows = [found[k] for k in sorted(found)]
    return table_text(["run_id", *paths, "seed", *MEASURED], rows), rejected


def checked_results(
    root: Path, warn: Callable[[str], None] | None = None
) -> tuple[list[str], list[dict[str, str]]]:
    """The header and rows of ``DIR/results.csv``, as its run files have them.

    ``results.csv`` is compared with the table rebuilt from the run files
    (:func:`rebuilt_text`); when they differ (a file cut short, binary, a wrong
    header, a row pasted in or left out) ``warn`` is told so in one line naming the
    file, which is then rewritten (atomically; left as it is where it cannot be) and
    the rebuilt rows are returned. Run files left out are named too.

    Raises
    ------
    SweepError
        ``DIR`` holds no usable ``sweep.json``.
    """
    warn = warn or (lambda line: print(f"warning: {line}", file=sys.stderr))
    root = Path(root)
    meta = read_meta(root)
    text, rejected = rebuilt_text(root, meta)
    for line in rejected[:5]:
        warn(line)
    if len(rejected) > 5:
        warn(f"{root / 'runs'}: {len(rejected) - 5} more run files left out")
    path = root / "results.csv"
    try:
        old = _read_bounded(path, 2_000_000_000)
    except FileNotFoundError:
        old = None
    except OSError:
        old = b""
    if old != text.encode("utf-8"):
        why = "missing" if old is None else "does not match the run files"
        try:
            write_atomic(path, text)
            n = len(meta.get("grid", {})) + len(meta.get("zip", {}))
            _write_parquet(root / "results.parquet", _header(text), text, n)
            warn(f"{path}: {why}; rebuilt from the run files")
        except OutputError as exc:
            warn(f"{path}: {why}; the table is rebuilt from the run files ({exc})")
    reader = csv.DictReader(io.StringIO(text, newline=""))
    rows = list(reader)
    return list(reader.fieldnames or []), rows


def _header(text: str) -> list[str]:
    return next(csv.reader(io.StringIO(text, newline="")))


def read_results(root: Path) -> tuple[list[str], list[dict[str, str]]]:
    """The header and rows of ``DIR/results.csv`` (see :func:`checked_results`)."""
    return checked_results(root)


def varied_paths(root: Path) -> list[str]:
    """The varied paths of the sweep in ``DIR`` (from ``sweep.json``)."""
    meta = read_meta(root)
    return [*meta.get("grid", {}), *meta.get("zip", {})]


def varied_axes(root: Path) -> list[tuple[str, ...]]:
    """The sweep's axes: each grid path alone, then the zipped paths as one axis."""
    meta = read_meta(root)
    axes = [(p,) for p in meta.get("grid", {})]
    if meta.get("zip"):
        axes.append(tuple(meta["zip"]))
    return axes
