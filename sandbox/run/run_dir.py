"""Run directories written atomically: the files of a run, and their manifest.

A run directory holds ``trajectory.csv``, ``metrics.json`` (its first entry,
``version``, names the version of sandbox that computed it, as the manifest does),
``scenario.yaml`` (the resolved scenario, runnable again) and ``run.npz`` (the recorded
arrays, for ``sandbox render`` and ``sandbox plot``). The whole directory is built
under a temporary name beside the target and then takes its place (see
:func:`write_run_dir`), so a killed run never leaves a truncated file that looks
complete, and re-running into a directory replaces the earlier run as a whole. A
directory that does not hold a run is never replaced. :meth:`Run.save
<sandbox.run.record.Run.save>`, ``sandbox run`` and a sweep's ``--keep-runs`` write
them; :func:`sandbox.run.output.load_run_dir` reads them back.

This module reads a run through its attributes only (``run: Any``): the record imports
it (``Run.save``), never the other way.
"""

from __future__ import annotations

import ctypes
import errno
import glob
import json
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from sandbox.errors import OutputError
from sandbox.run.codes import MODE_NAMES
from sandbox.run.output_guard import process_alive

__all__ = [
    "CSV_HEADER",
    "FILES",
    "MANIFEST",
    "PRODUCT_FILES",
    "check_out_dir",
    "read_manifest",
    "write_csv",
    "write_json",
    "write_run_dir",
    "write_text_atomic",
]

CSV_HEADER = "t,vehicle,x1,x2,x3,v1,v2,chi1,chi2,mode,failed"
FILES = ("trajectory.csv", "metrics.json", "scenario.yaml", "run.npz")


def write_csv(run: Any, path: Path) -> None:
    """Write ``trajectory.csv``: one row per vehicle per recorded sample.

    Streamed one sample at a time (memory stays that of one sample whatever the run's
    length), each sample formatted by a single ``%`` operation over a template of ``n``
    rows with the names filled in: about 5 us per row, most of it formatting the floats.
    """
    n = len(run.names)
    modes = np.array(MODE_NAMES, dtype=object)
    template = "%s,%s,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%s,%d\n" * n
    cells = np.empty((n, 11), dtype=object)
    cells[:, 1] = run.names
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(CSV_HEADER + "\n")
        for k in range(len(run.t)):
            cells[:, 0] = f"{run.t[k]:.6f}"
            cells[:, 2:5] = run.pose[k]
            cells[:, 5:7] = run.cmd[k]
            cells[:, 7:9] = run.chi[k]
            cells[:, 9] = modes[run.mode[k]]
            cells[:, 10] = run.failed[k]
            fh.write(template % tuple(cells.ravel()))


def write_json(data: Any, path: Path) -> None:
    """Write JSON with a trailing newline; NaN and infinities are written as ``null``.

    (A diverged run can have non-finite metrics; JSON has no literal for them.)
    """
    text = json.dumps(_finite(data), indent=2, allow_nan=False) + "\n"
    path.write_text(text, encoding="utf-8")


def _finite(data: Any) -> Any:
    """``data`` with every non-finite float replaced by None."""
    if isinstance(data, dict):
        return {k: _finite(v) for k, v in data.items()}
    if isinstance(data, list | tuple):
        return [_finite(v) for v in data]
    if isinstance(data, float | np.floating):
        return float(data) if math.isfinite(data) else None
    if isinstance(data, np.integer):
        return int(data)
    return data


def write_text_atomic(path: Path, text: str) -> None:
    """Write a text file whole or not at all (a temporary file, then a rename)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        reason = exc.strerror or exc
        raise OutputError(f"{path}: cannot be written ({reason})") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_run_dir(
    run: Any, metrics: dict[str, Any], out_dir: Path, trajectory: str = "csv"
) -> Path:
    """Write a run's outputs into ``out_dir``, replacing an earlier run there.

    ``trajectory`` chooses ``trajectory.csv`` (``"csv"``) or ``trajectory.parquet``
    (``"parquet"``, the same columns; needs pyarrow, the ``analysis`` extra).

    The files and their manifest (:data:`MANIFEST`) are written into a temporary
    directory beside ``out_dir`` (named ``.<name>.tmp-<pid>-...``), which then takes
    the place of ``out_dir``: with one atomic exchange where the system offers it
    (Linux ``renameat2``), else by two renames. A run killed at any moment leaves
    either the earlier complete run or the new complete one, never a mix.

    An existing ``out_dir`` is replaced only if it is empty or holds a valid manifest
    (see :func:`check_out_dir`), and everything in it that the manifest does not list
    (``figures/`` that ``sandbox plot`` wrote, notes, runs nested in it) is kept: it is
    moved into the new run directory. Writers of one parent directory are serialised by
    a lock on that directory, so two runs creating the same new directory both
    succeed, one after the other. Leftovers of killed runs are cleaned up by the next
    write (see :func:`_remove_leftovers`).

    Returns the directory. Raises :class:`~sandbox.errors.OutputError` if it cannot.
    """
    out_dir = Path(out_dir)
    check_out_dir(out_dir)
    parent = out_dir.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        with _DirLock(parent):
            _remove_leftovers(parent, out_dir.name)
        tmp = Path(
            tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-{os.getpid()}-", dir=parent)
        )
        os.chmod(tmp, 0o777 & ~_umask())
    except OSError as exc:
        raise OutputError(
            f"{out_dir}: cannot create the output directory ({_reason(exc)})"
        ) from None
    try:
        if trajectory == "parquet":
            from sandbox.run.analysis import write_parquet

            write_parquet(run, tmp / "trajectory.parquet")
        else:
            write_csv(run, tmp / "trajectory.csv")
        write_json(_versioned(metrics), tmp / "metrics.json")
        if run.scenario is not None:
            text = yaml.safe_dump(run.scenario.to_dict(), sort_keys=False)
            (tmp / "scenario.yaml").write_text(text, encoding="utf-8")
        run.save_npz(tmp / "run.npz")
        _write_manifest(tmp)
        with _DirLock(parent):
            check_out_dir(out_dir)  # again: another writer may have made it meanwhile
            _swap_into_place(tmp, out_dir)
    except OSError as exc:
        _remove_product_files(tmp, restore_to=out_dir)
        raise OutputError(f"{out_dir}: cannot write the run ({_reason(exc)})") from None
    except BaseException:
        _remove_product_files(tmp, restore_to=out_dir)
        raise
    return out_dir


def _reason(exc: OSError) -> str:
    """An OS error's reason, without the hidden temporary names it may carry."""
    return exc.strerror or type(exc).__name__


#: The file that marks a directory as a run directory written by sandbox.
MANIFEST = "manifest.json"
#: Every name the product writes into a run directory (a manifest lists some of them;
#: nothing else is ever deleted from a run directory).
PRODUCT_FILES = frozenset({*FILES, "trajectory.parquet", MANIFEST})
_MANIFEST_MAX_BYTES = 65536


def _versioned(metrics: dict[str, Any]) -> dict[str, Any]:
    """``metrics`` with ``version`` first: the version of sandbox writing them."""
    from sandbox._about import __version__

    return {
        "version": __version__,
        **{k: v for k, v in metrics.items() if k != "version"},
    }


def _write_manifest(run_dir: Path) -> None:
    """Write the manifest: the product, its version and the files it wrote.

    It holds no time or host, so identical runs give identical manifests.
    """
    from sandbox._about import __version__

    files = sorted(p.name for p in run_dir.iterdir() if p.name != MANIFEST)
    doc = {
        "product": "sandbox",
        "version": __version__,
        "format": 1,
        "files": files,
    }
    write_json(doc, run_dir / MANIFEST)


def read_manifest(run_dir: Path) -> set[str] | None:
    """The files a valid manifest of ``run_dir`` lists, or None if it has none.

    Valid: a regular file (not a link) of at most 64 KiB holding a JSON object with
    ``"product": "sandbox"`` and a ``files`` list of names the product writes. Names a
    manifest lists beyond those (a crafted or damaged one) make it invalid.
    """
    path = Path(run_dir) / MANIFEST
    try:
        if path.is_symlink() or not path.is_file():
            return None
        if path.stat().st_size > _MANIFEST_MAX_BYTES:
            return None
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    if not isinstance(doc, dict) or doc.get("product") != "sandbox":
        return None
    files = doc.get("files")
    if not isinstance(files, list) or not all(
        isinstance(f, str) and f in PRODUCT_FILES for f in files
    ):
        return None
    return {*files, MANIFEST}


def check_out_dir(out_dir: Path) -> None:
    """Raise :class:`~sandbox.errors.OutputError` if ``out_dir`` must not be replaced.

    It may be missing, empty or a run directory with a valid manifest (see
    :func:`read_manifest`); not a file or a link, not a directory without a manifest
    (a run directory written by sandbox 0.1 has none: remove it or choose another
    ``--out``), not the working directory or one of its parents. Of a run directory
    only the files its manifest lists are replaced; other entries are kept, unless
    one of them has the name of a file the product writes (then it is refused, naming
    them).
    """
    out_dir = Path(out_dir)
    if not out_dir.exists() and not out_dir.is_symlink():
        return
    if out_dir.is_symlink() or not out_dir.is_dir():
        raise OutputError(
            f"{out_dir}: exists and is not a directory; choose another --out"
        )
    here = Path.cwd().resolve()
    target = out_dir.resolve()
    if target == here or target in here.parents:
        raise OutputError(
            f"{out_dir}: is the working directory or holds it; choose another --out"
        )
    try:
        entries = {p.name for p in out_dir.iterdir()}
    except OSError as exc:
        raise OutputError(f"{out_dir}: cannot be read ({_reason(exc)})") from None
    if not entries:
        return
    listed = read_manifest(out_dir)
    if listed is None:
        raise OutputError(
            f"{out_dir}: exists and is not a run directory (no valid {MANIFEST}), so "
            "nothing in it is replaced; choose another --out"
        )
    clash = sorted((entries - listed) & PRODUCT_FILES)
    if clash:
        raise OutputError(
            f"{out_dir}: holds {', '.join(clash)}, which the run would write but its "
            f"{MANIFEST} does not list, so it is not replaced; move "
            f"{'them' if len(clash) > 1 else 'it'} away or choose another --out"
        )


def _kept_entries(out_dir: Path) -> list[str]:
    """Entries of an existing run directory that its manifest does not list."""
    listed = read_manifest(out_dir) or set()
    return sorted(p.name for p in out_dir.iterdir() if p.name not in listed)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


class _DirLock:
    """An exclusive ``flock`` on a directory, held while a run directory is swapped.

    Serialises the writers of one parent directory (processes and threads). Where
    directories cannot be locked (not POSIX, some network file systems) it does
    nothing, and the swap itself retries when another writer got there first.
    """

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.fd: int | None = None

    def __enter__(self) -> _DirLock:
        try:
            import fcntl

            self.fd = os.open(self.directory, os.O_RDONLY)
            fcntl.flock(self.fd, fcntl.LOCK_EX)
        except (ImportError, OSError):
            if self.fd is not None:
                os.close(self.fd)
            self.fd = None
        return self

    def __exit__(self, *exc: object) -> None:
        if self.fd is not None:
            os.close(self.fd)  # releases the lock
            self.fd = None


def _remove_leftovers(parent: Path, name: str) -> None:
    """Clean up what killed runs left beside ``parent/name``, touching only our files.

    A leftover is a directory ``.<name>.tmp-<pid>-*`` or ``.<name>.old-<pid>-*`` whose
    process is dead. Of its entries only the regular files the product writes
    (:data:`PRODUCT_FILES`) are deleted; anything else in it (a user's file caught
    while being carried into a new run directory) is moved back into ``parent/name``
    when that has no entry of the same name, and otherwise left where it is. A
    ``.old-`` directory whose run never got replaced (killed between the two renames
    of the fallback swap) is put back as ``parent/name``. The directory is removed
    only once empty.
    """
    target = parent / name
    for prefix in (f".{name}.tmp-", f".{name}.old-"):
        for path in parent.glob(f"{glob.escape(prefix)}*"):
            pid = path.name[len(prefix) :].split("-", 1)[0]
            if not pid.isdigit() or process_alive(int(pid)):
                continue
            if path.is_symlink() or not path.is_dir():
                continue
            if not target.exists() and prefix.endswith(".old-"):
                if read_manifest(path) is not None:
                    os.replace(path, target)
                    continue
            _remove_product_files(path, restore_to=target)


def _remove_product_files(directory: Path, restore_to: Path | None = None) -> None:
    """Delete the product's regular files in ``directory``, then it if it is empty.

    Other entries are moved into ``restore_to`` (where it exists and has no entry of
    that name) or left in place.
    """
    try:
        entries = list(directory.iterdir())
    except OSError:
        return
    for entry in entries:
        try:
            if (
                entry.name in PRODUCT_FILES
                and entry.is_file()
                and not entry.is_symlink()
            ):
                entry.unlink()
            elif restore_to is not None and restore_to.is_dir():
                dest = restore_to / entry.name
                if not dest.exists() and not dest.is_symlink():
                    os.replace(entry, dest)
        except OSError:
            pass
    try:
        directory.rmdir()
    except OSError:
        pass


def _swap_into_place(tmp: Path, out_dir: Path) -> None:
    """Put ``tmp`` in the place of ``out_dir``, carrying over what it did not write.

    The entries of an earlier ``out_dir`` that its manifest does not list are moved
    into the new directory right after the swap; the earlier run's own files are then
    deleted.
    """
    if not out_dir.exists():
        try:
            os.replace(tmp, out_dir)
            return
        except OSError as exc:  # another writer made it first (no lock here)
            if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                raise
            check_out_dir(out_dir)
    keep = _kept_entries(out_dir)
    if _exchange(tmp, out_dir):  # tmp now holds the earlier run
        old = tmp
    else:
        old = Path(
            tempfile.mkdtemp(
                prefix=f".{out_dir.name}.old-{os.getpid()}-", dir=out_dir.parent
            )
        )
        os.rmdir(old)
        os.replace(out_dir, old)
        try:
            os.replace(tmp, out_dir)
        except BaseException:
            os.replace(old, out_dir)  # put the earlier run back
            raise
    for name in keep:
        os.replace(old / name, out_dir / name)
    _remove_product_files(old, restore_to=out_dir)


_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def _exchange(a: Path, b: Path) -> bool:
    """Swap two directories in one atomic step; False where the system cannot."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = (
        ctypes.c_int,
        ctypes.c_char_p,
        ctypes.c_int,
        ctypes.c_char_p,
        ctypes.c_uint,
    )
    renameat2.restype = ctypes.c_int
    if (
        renameat2(
            _AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE
        )
        == 0
    ):
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.EPERM):
        return False
    raise OSError(err, os.strerror(err), str(b))
