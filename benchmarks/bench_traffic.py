"""Inter-platoon contacts of the traffic scenes over random seeds, Wilson intervals.

The runs come from the sweep engine, one store per scene (each run's ``metrics.json``
is kept in the store, ``runs/<id>.json``)::

    for s in intersection_two intersection_four head_on_narrow merge_one_lane \\
             overtaking roundabout failure_crash failure_stop; do
      sandbox sweep scenarios/traffic/$s.yaml --seeds 0:100 \\
        --zip recovery.strategy=none,continuous,continuous,continuous \\
        --zip recovery.tangential=0,0,1,1 --zip safety.filter=none,none,none,cbf \\
        --jobs 2 --out studies/traffic/$s
    done
    python benchmarks/bench_traffic.py studies/traffic \
        --figure renders/traffic/contacts.png

The four settings: no recovery; the report's continuous strategy (beta = 1, R = 3d,
r = R/2); the same with the tangential term (kappa = 1); and with the CBF filter on
top (the recommended configuration, as the scenes are written). For each scene and
setting the script prints the share of runs with at least one inter-platoon contact
(``collisions.inter_platoon > 0``) with its Wilson 95 % interval, the mean number of
inter-platoon contacts per run, the share of runs in which every platoon converged,
and the runs that deadlocked; ``sandbox sweep table DIR`` gives the engine's own table
(collisions of healthy vehicles, settling) of the same runs.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from sandbox.study.summary import wilson

#: The settings in the order of the table, keyed by their sweep values.
SETTINGS = {
    ("none", "0", "none"): "no recovery",
    ("continuous", "0", "none"): "continuous (report)",
    ("continuous", "1", "none"): "+ tangential (kappa = 1)",
    ("continuous", "1", "cbf"): "+ CBF filter (recommended)",
}


def scene_rows(store: Path) -> list[list[str]]:
    """The table rows of one scene's store: one per setting."""
    groups: dict[tuple[str, str, str], list[dict]] = {}
    for path in sorted((store / "runs").glob("*.json")):
        doc = json.loads(path.read_text(encoding="utf-8"))
        v = doc["values"]
        key = (v["recovery.strategy"], v["recovery.tangential"], v["safety.filter"])
        groups.setdefault(key, []).append(doc)
    rows = []
    for key, label in SETTINGS.items():
        runs = groups.get(key, [])
        n = len(runs)
        if not n:
            continue
        inter = [r["metrics"]["collisions"]["inter_platoon"] for r in runs]
        hit = sum(1 for c in inter if c > 0)
        lo, hi = wilson(hit, n)
        conv = sum(
            1
            for r in runs
            if all(p["converged"] for p in r["metrics"]["platoons"].values())
        )
        dead = sum(1 for r in runs if r["metrics"].get("deadlocks"))
        rows.append(
            [
                store.name,
                label,
                str(n),
                f"{hit}",
                f"{100 * hit / n:.0f} % [{100 * lo:.0f}, {100 * hi:.0f}]",
                f"{sum(inter) / n:.2f}",
                f"{100 * conv / n:.0f} %",
                str(dead),
            ]
        )
    return rows


HEADER = [
    "scene",
    "setting",
    "runs",
    "runs with an inter-platoon contact",
    "rate [Wilson 95 %]",
    "inter-platoon contacts per run",
    "all platoons converged",
    "runs with a deadlock",
]


def main() -> None:
    """Print the Markdown table of every store under the folder; draw the figure."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a folder of sweep stores")
    parser.add_argument("--figure", type=Path, help="write the rates figure here")
    args = parser.parse_args()
    stores = sorted(p for p in args.folder.iterdir() if (p / "runs").is_dir())
    rows = [row for store in stores for row in scene_rows(store)]
    print("| " + " | ".join(HEADER) + " |")
    print("|" + "---|" * len(HEADER))
    for row in rows:
        print("| " + " | ".join(row) + " |")
    if args.figure is not None:
        _figure(stores, args.figure)


def _figure(stores: list[Path], path: Path) -> None:
    """Bars of the inter-platoon contact rate per scene and setting, with intervals."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4.6), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    width = 0.8 / len(SETTINGS)
    for j, label in enumerate(SETTINGS.values()):
        rates, los, his = [], [], []
        for store in stores:
            found = [r for r in scene_rows(store) if r[1] == label]
            hit, n = (int(found[0][3]), int(found[0][2])) if found else (0, 0)
            lo, hi = wilson(hit, n) if n else (np.nan, np.nan)
            rate = hit / n if n else np.nan
            rates.append(100 * rate)
            los.append(100 * (rate - lo))
            his.append(100 * (hi - rate))
        x = np.arange(len(stores)) + (j - (len(SETTINGS) - 1) / 2) * width
        ax.bar(x, rates, width, yerr=[los, his], capsize=3, label=label)
        for xi, r, up in zip(x, rates, his, strict=True):
            if np.isfinite(r):
                ax.text(
                    xi, r + up + 1, f"{r:.0f}", ha="center", va="bottom", fontsize=7
                )
    ax.set_xticks(np.arange(len(stores)), [s.name for s in stores], rotation=15)
    ax.set_ylabel("runs with an inter-platoon contact [%]")
    ax.set_ylim(0, 110)
    ax.grid(True, axis="y", lw=0.4, alpha=0.5)
    fig.legend(loc="outside lower center", fontsize="small", ncols=len(SETTINGS))
    ax.set_title("Traffic scenes: inter-platoon contacts (Wilson 95 % intervals)")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
