"""``sandbox compare``: one row per scenario and recovery setting, deterministic."""

from __future__ import annotations

import csv
import io
import json

import pytest
from helpers import PAPER, SCENARIOS, run_scenario

from sandbox.cli import main
from sandbox.study.compare import cases, compare, format_table

FIG13 = PAPER / "fig13_discontinuous_beta1.yaml"
STOP = SCENARIOS / "failures" / "follower_stop.yaml"
SHORT = ("duration=5",)


@pytest.mark.slow
def test_rows_are_the_runs_metrics():
    rows = compare([FIG13, STOP], ["none", "continuous"], ["hold"], SHORT)
    assert [(r.scenario, r.strategy, r.derivatives) for r in rows] == [
        ("fig13_discontinuous_beta1", "none", "hold"),
        ("fig13_discontinuous_beta1", "continuous", "hold"),
        ("follower_stop", "none", "hold"),
        ("follower_stop", "continuous", "hold"),
    ]
    for row, path in zip(rows, [FIG13, FIG13, STOP, STOP], strict=True):
        _, m = run_scenario(path, *SHORT, f"recovery.strategy={row.strategy}")
        assert row.collisions_total == m["collisions"]["total"]
        assert row.collisions_healthy == m["collisions"]["healthy"]
        assert row.min_distance == m["min_distance"]
        vehicles = m["vehicles"]
        assert row.mode_switches == sum(v["mode_switches"] for v in vehicles.values())
        assert row.control_effort == pytest.approx(
            sum(v["control_effort"] for v in vehicles.values())
        )
        assert row.converged == m["converged"]
        # the latest settling over the healthy vehicles: red, failed, is left out
        healthy = [v for v in vehicles.values() if v["failed_at"] is None]
        settle = [v["settling_time"] for v in healthy]
        assert row.settling_time == (None if None in settle else max(settle))
    # without recovery orange hits the stopped red: a collision, but not a healthy one
    assert rows[2].collisions_total > 0 and rows[2].collisions_healthy == 0


def test_none_runs_once_and_estimate_differs_from_hold():
    assert cases(["none", "smooth"], ["hold", "estimate"]) == [
        ("none", "hold"),
        ("smooth", "hold"),
        ("smooth", "estimate"),
    ]
    rows = compare([FIG13], ["discontinuous"], ["hold", "estimate"], SHORT)
    assert [r.derivatives for r in rows] == ["hold", "estimate"]
    assert rows[0] != rows[1]


#: The arguments of the rows the tests below share (computed once per module).
FIG13_ARGS = ([FIG13], ["none", "smooth"], ["hold"], SHORT)


@pytest.fixture(scope="module")
def fig13_rows():
    return compare(*FIG13_ARGS)


@pytest.mark.slow
def test_deterministic_in_one_or_two_processes(fig13_rows):
    one = format_table(fig13_rows, "csv")
    assert one == format_table(compare(*FIG13_ARGS), "csv")
    assert one == format_table(compare(*FIG13_ARGS, jobs=2), "csv")


@pytest.mark.slow
def test_markdown_and_csv_tables(fig13_rows):
    rows = fig13_rows
    md = format_table(rows).splitlines()
    assert md[0].startswith("| scenario ") and "collisions healthy" in md[0]
    assert set(md[1]) <= {"|", "-", ":", " "}
    assert len(md) == 2 + len(rows)
    assert format_table(rows, "markdown") == format_table(rows, "md")
    parsed = list(csv.DictReader(io.StringIO(format_table(rows, "csv"))))
    assert [r["strategy"] for r in parsed] == ["none", "smooth"]
    assert parsed[0]["converged"] in ("true", "false")
    assert [r["status"] for r in parsed] == [r.status for r in rows]
    assert int(parsed[0]["collisions_total"]) == rows[0].collisions_total
    # full precision in CSV and JSON: the numbers read back exactly
    assert [float(r["control_effort"]) for r in parsed] == [
        r.control_effort for r in rows
    ]
    doc = json.loads(format_table(rows, "json"))
    assert [d["min_distance"] for d in doc] == [r.min_distance for r in rows]
    assert [d["converged"] for d in doc] == [r.converged for r in rows]
    with pytest.raises(ValueError, match="unknown format"):
        format_table(rows, "html")


@pytest.mark.slow
def test_cli(capsys):
    argv = ["compare", str(FIG13), "--strategies", "none,continuous", "--format", "csv"]
    assert main([*argv, "--set", "duration=3"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].startswith("scenario,strategy,derivatives,collisions_healthy")
    assert len(lines) == 3
    argv[-1] = "json"
    assert main([*argv, "--set", "duration=1"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [d["strategy"] for d in doc] == ["none", "continuous"]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--strategies", "none,fast"], "unknown strategy 'fast'"),
        (["--derivatives", "guess"], "unknown target_derivatives 'guess'"),
        (["--set", "recovery.bta=2"], "did you mean 'beta'?"),
    ],
)
def test_cli_rejects_bad_input_before_running(capsys, extra, message):
    assert main(["compare", str(FIG13), *extra]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
def test_file_strategy_keeps_each_files_recovery():
    fig12 = PAPER / "fig12_no_recovery.yaml"
    fig15 = PAPER / "fig15_continuous_beta5.yaml"
    rows = compare([fig12, fig15], ["file"], ["hold", "estimate"], SHORT)
    # fig12 has no recovery: run once, with hold
    assert [(r.scenario, r.strategy, r.derivatives) for r in rows] == [
        ("fig12_no_recovery", "none", "hold"),
        ("fig15_continuous_beta5", "continuous", "hold"),
        ("fig15_continuous_beta5", "continuous", "estimate"),
    ]
    _, m = run_scenario(fig15, *SHORT)
    assert rows[1].control_effort == pytest.approx(
        sum(v["control_effort"] for v in m["vehicles"].values())
    )


SWAP = SCENARIOS / "safety" / "head_on_swap.yaml"


@pytest.mark.slow
def test_grid_varies_a_path_per_strategy_and_none_only_once():
    rows = compare(
        [SWAP],
        ["none", "continuous"],
        ["hold"],
        ("duration=6",),
        grid=["recovery.tangential=0,1"],
    )
    assert [(r.strategy, r.setting) for r in rows] == [
        ("none", "tangential=0"),
        ("continuous", "tangential=0"),
        ("continuous", "tangential=1"),
    ]
    stalled, passed = rows[1], rows[2]
    # the symmetric stall of the radial field, and the way out (measured)
    assert stalled.deadlocks == 1 and not stalled.success
    assert stalled.extra_settle is None
    assert passed.deadlocks == 0 and passed.converged
    # one brief contact of the closing approach: converged, but no success
    assert passed.collisions_total == 1 and not passed.success
    assert passed.separation == pytest.approx(passed.min_distance - 0.5)
    assert passed.extra_settle is not None and passed.extra_settle > 0
    assert passed.control_ms > 0


def test_extra_settle_is_over_the_ideal_run_without_recovery():
    from sandbox.study.compare import ideal_settling

    (row,) = compare([SWAP], ["continuous"], ["hold"], ("duration=6",))
    base = ideal_settling(str(SWAP), ("duration=6",))
    assert base is not None and row.settling_time is not None
    assert row.extra_settle == pytest.approx(row.settling_time - base)


def test_safety_columns_and_a_bad_grid(capsys):
    argv = ["compare", str(SWAP), "--strategies", "continuous", "--set", "duration=4"]
    assert main([*argv, "--grid", "recovery.tangential=1", "--columns", "safety"]) == 0
    head = capsys.readouterr().out.splitlines()[0]
    for name in ("success", "deadlocks", "min separation - d", "extra settle"):
        assert name in head
    assert "measured" in head
    assert main([*argv, "--grid", "recovery.tangential"]) == 2
    assert "expected PATH=v1,v2" in capsys.readouterr().err
