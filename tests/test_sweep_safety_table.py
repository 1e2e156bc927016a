"""``sandbox sweep table DIR --safety``: the filter's figures of each group."""

from __future__ import annotations

import json
from pathlib import Path

from sandbox.cli import main

ROOT = Path(__file__).resolve().parents[1]
RING = ROOT / "scenarios" / "safety" / "circle_swap_3.yaml"


def test_the_safety_table_counts_the_runs_with_relaxed_steps(tmp_path, capsys):
    out = tmp_path / "study"
    argv = ["sweep", str(RING), "--set", "duration=0.5", "--set", "safety.filter=cbf"]
    argv += ["--grid", "safety.barrier=velocity,braking", "--seeds", "0:2"]
    assert main([*argv, "--out", str(out)]) == 0
    # One run made to have relaxed: its file's infeasible_steps set by hand.
    path = sorted((out / "runs").glob("*.json"))[0]
    doc = json.loads(path.read_text())
    doc["metrics"]["safety"]["infeasible_steps"] = 3
    path.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["sweep", "table", str(out), "--safety", "--format", "json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["safety.barrier"] for r in rows] == ["velocity", "braking"]
    assert [r["runs"] for r in rows] == [2, 2]
    assert sum(r["relaxed"] for r in rows) == 1
    assert sum(r["relaxed_steps"] for r in rows) == 3
    hit = next(r for r in rows if r["relaxed"])
    # Wilson 95 % of 1 / 2: centre (0.5 + 0.9604) / 2.9208, half 0.4376 / 1.4604 ...
    assert 0.09 < hit["relaxed_low"] < 0.1 and 0.90 < hit["relaxed_high"] < 0.91
