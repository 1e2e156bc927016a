"""Run directories read back, every member checked; the writers' public path.

:func:`load_run_dir` reads a directory written by
:func:`sandbox.run.run_dir.write_run_dir` (``sandbox run``, :meth:`Run.save
<sandbox.run.record.Run.save>`) and refuses, in one line naming the file and the
member, one that is damaged or crafted. The writers are
:mod:`sandbox.run.run_dir`'s, also importable from here.
"""

from __future__ import annotations

import warnings
import zipfile
from pathlib import Path

from sandbox.errors import OutputError, SandboxWarning
from sandbox.run.record import Run, RunFileError
from sandbox.run.run_dir import (
    CSV_HEADER,
    FILES,
    MANIFEST,
    PRODUCT_FILES,
    check_out_dir,
    read_manifest,
    write_csv,
    write_json,
    write_run_dir,
    write_text_atomic,
)
from sandbox.scenario import load_scenario

__all__ = [
    "CSV_HEADER",
    "FILES",
    "MANIFEST",
    "PRODUCT_FILES",
    "check_out_dir",
    "RunDirError",
    "load_run_dir",
    "read_manifest",
    "write_csv",
    "write_json",
    "write_run_dir",
    "write_text_atomic",
]


class RunDirError(OutputError):
    """Not a valid run directory: missing, damaged or crafted (names the member).

    The command line prints the message as one line and exits with status 2.
    """

    #: The command line's exit status: invalid input.
    exit_status = 2


#: What reading a damaged or foreign ``run.npz`` can raise.
_DAMAGED = (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile)


def load_run_dir(run_dir: Path) -> Run:
    """Read back a run directory written by :func:`write_run_dir`.

    Every member of ``run.npz`` is checked before anything reads it (members, dtypes,
    shapes against the number of samples and vehicles, sizes before inflating, the
    values, and each entry of the metadata that is read: see
    :mod:`sandbox.run.run_file`), so a crafted or damaged directory is refused with a
    :class:`RunDirError` (``not a valid run directory: DIR (run.npz: MEMBER: ...)``,
    one line) before the metrics, the pictures or the replay read it.
    """
    run_dir = Path(run_dir)
    npz = run_dir / "run.npz"
    if not npz.is_file():
        raise RunDirError(
            f"not a valid run directory: {run_dir} (no run.npz; run a scenario "
            "with 'sandbox run FILE --out DIR' first)"
        )
    scenario = None
    if (run_dir / "scenario.yaml").is_file():
        with warnings.catch_warnings():  # the run is made: its scenario warned then
            warnings.simplefilter("ignore", SandboxWarning)
            scenario = load_scenario(run_dir / "scenario.yaml")
    try:
        # An open file we own: numpy leaves its own file open when the zip is damaged.
        with open(npz, "rb") as fh:
            run = Run.load_npz(fh, scenario)
    except RunFileError as exc:
        raise RunDirError(
            f"not a valid run directory: {run_dir} (run.npz: {exc})"
        ) from None
    except _DAMAGED as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise RunDirError(
            f"not a valid run directory: {run_dir} (run.npz: damaged, cannot be read: "
            f"{reason})"
        ) from None
    if scenario is not None and [v.name for v in scenario.vehicles] != run.names:
        raise RunDirError(
            f"not a valid run directory: {run_dir} (scenario.yaml names other vehicles "
            "than run.npz)"
        )
    return run
