"""The page of a sweep: its results table, sortable and filterable, linking replays.

``sandbox sweep view DIR`` writes ``DIR/sweep.html``: the rows of ``DIR/results.csv``
(:func:`sandbox.study.store.read_results`), sortable by any column and filterable by
status and collisions, each row linking its run's replay page when the sweep kept its
run directory (``sandbox sweep ... --keep-runs`` writes ``DIR/run_dirs/<run id>/``).
The replay of a kept run is written beside it (``replay.html``) when it is missing.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sandbox.render.replay.page import (
    ReplayError,
    build_page,
    check_output,
    is_page,
    write_page,
)
from sandbox.study.sweep import KEPT_RUNS

__all__ = ["KEPT_RUNS", "sweep_data", "write_sweep_html"]
#: The name of a kept run's replay page.
REPLAY_NAME = "replay.html"


def sweep_data(root: Path, links: dict[str, str]) -> dict[str, Any]:
    """The mapping the sweep page embeds.

    Parameters
    ----------
    root : Path
        The sweep directory.
    links : dict
        Run id -> the relative address of its replay page.

    Returns
    -------
    dict
        ``name``, ``header``, ``rows`` (lists of the CSV's texts), ``varied``,
        ``links``, ``kept`` (how many runs have a replay).
    """
    from sandbox.study.store import read_results, varied_paths

    header, rows = read_results(root)
    try:
        varied = varied_paths(root)
    except (OSError, ValueError):
        varied = []
    return {
        "format": 1,
        "name": Path(root).resolve().name,
        "header": header,
        "rows": [[row.get(h, "") or "" for h in header] for row in rows],
        "varied": varied,
        "links": links,
        "kept": len(links),
    }


def _replays(
    root: Path, run_ids: list[str], log: Callable[[str], None] | None
) -> dict[str, str]:
    """Write the missing replay pages of the kept runs; their addresses by run id."""
    from sandbox.errors import SandboxError
    from sandbox.render.replay import write_html
    from sandbox.run.output import load_run_dir

    links = {}
    for run_id in run_ids:
        run_dir = root / KEPT_RUNS / run_id
        if not (run_dir / "run.npz").is_file():
            continue
        page = run_dir / REPLAY_NAME
        if page.is_file() and not is_page(page):
            if log is not None:
                log(f"warning: {page}: not a replay page; not linked")
            continue
        if not page.is_file():
            try:
                write_html(load_run_dir(run_dir), page)
            except SandboxError as exc:
                if log is not None:
                    log(f"warning: {run_id}: no replay ({exc})")
                continue
        links[run_id] = f"{KEPT_RUNS}/{run_id}/{REPLAY_NAME}"
    return links


def write_sweep_html(
    root: str | os.PathLike[str],
    path: str | os.PathLike[str] | None = None,
    *,
    replays: bool = True,
    log: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Write the page of the sweep in ``root``.

    Parameters
    ----------
    root : str or os.PathLike
        A sweep directory (``results.csv`` and ``sweep.json``).
    path : str or os.PathLike, optional
        The page; default ``root/sweep.html``. Links to the replays are relative to
        ``root``, so the page belongs in it (elsewhere, they are made relative to it).
    replays : bool
        Write the missing replay pages of the kept runs first.
    log : callable, optional
        Called with a line per kept run whose replay cannot be written.

    Returns
    -------
    dict
        ``path``, ``rows`` and ``replays`` (how many rows link a replay).

    Raises
    ------
    ReplayError
        ``root`` is not a sweep directory, or ``path`` must not be written.
    """
    root = Path(root)
    out = Path(path) if path is not None else root / "sweep.html"
    if not (root / "results.csv").is_file() or not (root / "sweep.json").is_file():
        raise ReplayError(
            f"{root}: not a sweep directory (no results.csv and sweep.json; run "
            "sandbox sweep FILE --out DIR first)"
        )
    check_output(out)
    from sandbox.study.spec import SweepError
    from sandbox.study.store import read_results

    try:
        header, rows = read_results(root)
    except SweepError as exc:
        raise ReplayError(str(exc)) from None
    ids = [row.get("run_id", "") for row in rows]
    links = _replays(root, ids, log) if replays else {}
    base = os.path.relpath(root.resolve(), out.resolve().parent)
    if base != ".":
        links = {k: f"{Path(base).as_posix()}/{v}" for k, v in links.items()}
    data = sweep_data(root, links)
    title = f"sweep {data['name']}"
    text = build_page("sweep.html", title, data, ["sweep.js"])
    write_page(out, text)
    return {"path": out, "rows": len(rows), "replays": len(links)}
