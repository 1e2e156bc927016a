"""Run directories: writing a run's outputs atomically, and reading them back.

A run directory holds ``trajectory.csv``, ``metrics.json``, ``scenario.yaml`` (the
resolved scenario, runnable again) and ``run.npz`` (the recorded arrays, for ``sandbox
render`` and ``sandbox plot``). The whole directory is built under a temporary name beside
the target and then renamed into place, so a killed run never leaves a truncated file that
looks complete, and re-running into a directory replaces the earlier run as a whole.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
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
    """Write ``trajectory.csv``: one row per vehicle per recorded sample."""
    modes = np.array(MODE_NAMES)
    names = np.array(run.names)
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(CSV_HEADER + "\n")
        for k in range(len(run.t)):
            p, c, chi = run.pose[k], run.cmd[k], run.chi[k]
            cols = np.column_stack((p, c, chi))
            body = "\n".join(
                f"{run.t[k]:.6f},{name},{r[0]:.9g},{r[1]:.9g},{r[2]:.9g},{r[3]:.9g},"
                f"{r[4]:.9g},{r[5]:.9g},{r[6]:.9g},{m},{int(f)}"
                for name, r, m, f in zip(
                    names, cols.tolist(), modes[run.mode[k]], run.failed[k], strict=True
                )
            )
            fh.write(body + "\n")


def write_json(data: Any, path: Path) -> None:
    """Write JSON with a trailing newline."""
    path.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n", encoding="utf-8")


def write_run_dir(run: Run, metrics: dict[str, Any], out_dir: Path) -> Path:
    """Write a run's outputs into ``out_dir``, replacing any earlier run there whole.

    Returns the directory. Raises :class:`~sandbox.errors.OutputError` if it cannot.
    """
    out_dir = Path(out_dir)
    parent = out_dir.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-", dir=parent))
    except OSError as exc:
        raise OutputError(f"{out_dir}: cannot create the output directory ({exc})") from None
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
        raise OutputError(f"{out_dir}: cannot write the run ({exc})") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir


def _swap_into_place(tmp: Path, out_dir: Path) -> None:
    """Rename ``tmp`` to ``out_dir``; an existing ``out_dir`` is moved aside, then removed."""
    old = None
    if out_dir.exists():
        if not out_dir.is_dir():
            raise OSError(f"{out_dir} exists and is not a directory")
        old = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.old-", dir=out_dir.parent))
        os.rmdir(old)
        os.replace(out_dir, old)
    os.replace(tmp, out_dir)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def load_run_dir(run_dir: Path) -> Run:
    """Read back a run directory written by :func:`write_run_dir`."""
    run_dir = Path(run_dir)
    npz = run_dir / "run.npz"
    if not npz.is_file():
        raise OutputError(f"{run_dir}: not a run directory (no run.npz; run a scenario "
                          "with 'sandbox run FILE --out DIR' first)")
    scenario = None
    if (run_dir / "scenario.yaml").is_file():
        scenario = load_scenario(run_dir / "scenario.yaml")
    try:
        return Run.load_npz(npz, scenario)
    except (OSError, ValueError, KeyError) as exc:
        raise OutputError(f"{npz}: cannot be read ({exc})") from None
