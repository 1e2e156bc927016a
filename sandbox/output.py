"""Run directories: writing a run's outputs atomically, and reading them back.

A run directory holds ``trajectory.csv``, ``metrics.json``, ``scenario.yaml`` (the
resolved scenario, runnable again) and ``run.npz`` (the recorded arrays, for ``sandbox
render`` and ``sandbox plot``). The whole directory is built under a temporary name
beside the target and then takes its place (see :func:`write_run_dir`), so a killed run
never leaves a truncated file that looks complete, and re-running into a directory
replaces the earlier run as a whole. A directory that does not hold a run is never
replaced.
"""

from __future__ import annotations

import ctypes
import errno
import glob
import json
import math
import os
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from sandbox.errors import OutputError
from sandbox.run import MODE_NAMES, Run
from sandbox.scenario import load_scenario

CSV_HEADER = "t,vehicle,x1,x2,x3,v1,v2,chi1,chi2,mode,failed"
FILES = ("trajectory.csv", "metrics.json", "scenario.yaml", "run.npz")


def write_csv(run: Run, path: Path) -> None:
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


def write_run_dir(run: Run, metrics: dict[str, Any], out_dir: Path) -> Path:
    """Write a run's outputs into ``out_dir``, replacing any earlier run there whole.

    The files are written into a temporary directory beside ``out_dir`` (named
    ``.<name>.tmp-<pid>-...``), which then takes the place of ``out_dir``: with one
    atomic exchange where the system offers it (Linux ``renameat2``), else by two
    renames. A run
    killed at any moment leaves either the earlier complete run or the new complete one
    (or, in the instant between the two renames of the fallback, no directory), never a
    mix; leftovers of killed runs are removed by the next write. An existing ``out_dir``
    is replaced only if it is empty or holds a run (``run.npz`` or ``metrics.json``).

    Returns the directory. Raises :class:`~sandbox.errors.OutputError` if it cannot.
    """
    out_dir = Path(out_dir)
    check_out_dir(out_dir)
    parent = out_dir.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        _remove_leftovers(parent, out_dir.name)
        tmp = Path(
            tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-{os.getpid()}-", dir=parent)
        )
        os.chmod(tmp, 0o777 & ~_umask())
    except OSError as exc:
        raise OutputError(
            f"{out_dir}: cannot create the output directory ({exc.strerror or exc})"
        ) from None
    try:
        write_csv(run, tmp / "trajectory.csv")
        write_json(metrics, tmp / "metrics.json")
        if run.scenario is not None:
            text = yaml.safe_dump(run.scenario.to_dict(), sort_keys=False)
            (tmp / "scenario.yaml").write_text(text, encoding="utf-8")
        run.save_npz(tmp / "run.npz")
        _swap_into_place(tmp, out_dir)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        reason = exc.strerror or exc
        raise OutputError(f"{out_dir}: cannot write the run ({reason})") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir


def check_out_dir(out_dir: Path) -> None:
    """Raise :class:`~sandbox.errors.OutputError` if ``out_dir`` must not be replaced.

    It may be missing, empty or hold an earlier run; not a file, not a directory of
    other files, not the working directory or one of its parents.
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
        raise OutputError(f"{out_dir}: cannot be read ({exc})") from None
    if entries and not entries & {"run.npz", "metrics.json"}:
        raise OutputError(
            f"{out_dir}: exists and is not a run directory (no run.npz or "
            "metrics.json), so it is not replaced; choose another --out"
        )


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _remove_leftovers(parent: Path, name: str) -> None:
    """Remove temporary directories that killed runs left beside ``parent/name``."""
    for prefix in (f".{name}.tmp-", f".{name}.old-"):
        for path in parent.glob(f"{glob.escape(prefix)}*"):
            pid = path.name[len(prefix) :].split("-", 1)[0]
            if pid.isdigit() and not _alive(int(pid)):
                shutil.rmtree(path, ignore_errors=True)


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _swap_into_place(tmp: Path, out_dir: Path) -> None:
    """Put ``tmp`` in the place of ``out_dir``; remove an earlier ``out_dir``."""
    if not out_dir.exists():
        os.replace(tmp, out_dir)
        return
    if _exchange(tmp, out_dir):  # tmp now holds the earlier run
        shutil.rmtree(tmp, ignore_errors=True)
        return
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
    shutil.rmtree(old, ignore_errors=True)


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


#: What reading a damaged or foreign ``run.npz`` can raise.
_DAMAGED = (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile)


def load_run_dir(run_dir: Path) -> Run:
    """Read back a run directory written by :func:`write_run_dir`."""
    run_dir = Path(run_dir)
    npz = run_dir / "run.npz"
    if not npz.is_file():
        raise OutputError(
            f"{run_dir}: not a run directory (no run.npz; run a scenario "
            "with 'sandbox run FILE --out DIR' first)"
        )
    scenario = None
    if (run_dir / "scenario.yaml").is_file():
        scenario = load_scenario(run_dir / "scenario.yaml")
    try:
        # An open file we own: numpy leaves its own file open when the zip is damaged.
        with open(npz, "rb") as fh:
            return Run.load_npz(fh, scenario)
    except _DAMAGED as exc:
        raise OutputError(f"{npz}: damaged, cannot be read ({exc})") from None
