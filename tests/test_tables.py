"""The one table writer of ``sandbox compare`` and ``sandbox sweep table``."""

from __future__ import annotations

import csv
import doctest
import io
import json
import math

import pytest

import sandbox.run.tables as tables
from sandbox.run.tables import Column, format_table, significant, table_format
from sandbox.study import compare as compare_module
from sandbox.study import summary

COLUMNS = [
    Column("name", "the name", text=True),
    Column("count"),
    Column("rate"),
    Column("delta", signed=True),
    Column("ok"),
]
ROWS = [
    {"name": "a", "count": 3, "rate": 1 / 3, "delta": 0.00012345, "ok": True},
    {"name": "b", "count": 0, "rate": math.nan, "delta": None, "ok": False},
]


def test_the_doctests_hold() -> None:
    assert doctest.testmod(tables).failed == 0


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (3.14159, "3.142"),  # 4 significant digits
        (1 / 3, "0.3333"),
        (2.0, "2"),
        (1234.5678, "1235"),
        (123456.7, "123457"),  # no exponent for a large number
        (0.000123456, "0.0001235"),
        (0.0, "0"),
        (-0.5, "-0.5"),
    ],
)
def test_markdown_rounds_to_four_significant_digits(value: float, text: str) -> None:
    assert significant(value) == text


def test_markdown_csv_and_json_of_the_same_rows() -> None:
    md = format_table(COLUMNS, ROWS, "md").splitlines()
    assert md == [
        "| the name | count |   rate |      delta |  ok |",
        "| -------- | ----: | -----: | ---------: | --: |",
        "| a        |     3 | 0.3333 | +0.0001234 | yes |",
        "| b        |     0 |      - |          - |  no |",
    ]
    assert format_table(COLUMNS, ROWS, "markdown") == format_table(COLUMNS, ROWS)
    text = format_table(COLUMNS, ROWS, "csv")
    assert text.splitlines()[0] == "name,count,rate,delta,ok"
    parsed = list(csv.DictReader(io.StringIO(text)))
    assert float(parsed[0]["rate"]) == 1 / 3  # full precision: reads back exactly
    assert float(parsed[0]["delta"]) == 0.00012345
    assert [p["ok"] for p in parsed] == ["true", "false"]
    assert parsed[1]["rate"] == "" and parsed[1]["delta"] == ""
    doc = json.loads(format_table(COLUMNS, ROWS, "json"))
    assert doc[0] == {
        "name": "a",
        "count": 3,
        "rate": 1 / 3,
        "delta": 0.00012345,
        "ok": True,
    }
    assert doc[1]["rate"] is None and doc[1]["ok"] is False


def test_an_unknown_format_names_the_known_ones() -> None:
    with pytest.raises(ValueError, match="expected one of: md, csv, json, markdown"):
        table_format("html")


def test_compare_and_sweep_summary_use_the_one_writer(monkeypatch) -> None:
    # Both modules hand their rows to sandbox.run.tables.format_table.
    calls = []

    def spy(columns, rows, fmt="md", digits=4):
        calls.append((tuple(c.key for c in columns), fmt))
        return ""

    monkeypatch.setattr(compare_module, "write_table", spy)
    monkeypatch.setattr(summary, "write_table", spy)
    row = compare_module.Row("s", "none", "hold", 0, 0, 1.0, 2.0, 0, 3.0, True, "ok")
    compare_module.format_table([row], "json")
    summary.format_table([(("1",), summary.summarize([]))], ["recovery.beta"], "csv")
    assert calls[0][0][:3] == ("scenario", "strategy", "derivatives")
    assert calls[0][0][-1] == "status" and calls[0][1] == "json"
    assert calls[1][0][:2] == ("recovery.beta", "runs") and calls[1][1] == "csv"
