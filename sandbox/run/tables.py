"""The one table writer: Markdown for people, CSV and JSON for programs.

``sandbox compare`` and ``sandbox sweep table`` print their tables with
:func:`format_table`, in one of :data:`FORMATS` (``--format``):

- ``md``: a Markdown table with a header of titles, text columns left-aligned and
  numbers right-aligned; floats rounded to :data:`DIGITS` significant digits, booleans
  ``yes``/``no``, a missing value (None, NaN) ``-``. ``markdown`` is accepted as an
  alias (:data:`ALIASES`).
- ``csv``: a header of column keys, then one line per row; floats at full precision
  (``repr``: they read back to the same number), booleans ``true``/``false``, a missing
  value empty.
- ``json``: a list of objects, one per row, by column key; numbers at full precision,
  booleans ``true``/``false``, a missing value ``null``.

The same rows give the same text: nothing here depends on time or place.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

#: The formats of :func:`format_table`.
FORMATS = ("md", "csv", "json")
#: Other accepted names of a format.
ALIASES = {"markdown": "md"}
#: Significant digits of a float in a Markdown table.
DIGITS = 4


@dataclass(frozen=True)
class Column:
    """One column of a table.

    Attributes
    ----------
    key : str
        The name in CSV headers and JSON objects (and the key of the row mappings).
    title : str
        The Markdown header; the key if empty.
    text : bool
        Left-aligned in Markdown (names, settings); numbers are right-aligned.
    signed : bool
        A float shown with its sign in Markdown (``+0.125``): a difference.
    """

    key: str
    title: str = ""
    text: bool = False
    signed: bool = False


def table_format(fmt: str) -> str:
    """The format named ``fmt`` (an alias resolved), or ValueError.

    >>> table_format("markdown")
    'md'
    """
    fmt = ALIASES.get(fmt, fmt)
    if fmt not in FORMATS:
        names = ", ".join([*FORMATS, *ALIASES])
        raise ValueError(f"unknown format {fmt!r} (expected one of: {names})")
    return fmt


def _missing(value: Any) -> bool:
    return value is None or (isinstance(value, float) and math.isnan(value))


def significant(value: float, digits: int = DIGITS, signed: bool = False) -> str:
    """A float rounded to ``digits`` significant digits, never in exponent form above 1.

    >>> significant(3.14159), significant(0.000123456), significant(123456.7)
    ('3.142', '0.0001235', '123457')
    >>> significant(2.0), significant(0.5, signed=True), significant(-1e-7)
    ('2', '+0.5', '-1e-07')
    """
    sign = "+" if signed else ""
    if math.isfinite(value) and value != 0 and math.log10(abs(value)) >= digits:
        return f"{value:{sign}.0f}"  # a large number: all its integer digits
    return f"{value:{sign}.{digits}g}"


def _markdown_cell(value: Any, column: Column, digits: int) -> str:
    if _missing(value):
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return significant(value, digits, column.signed)
    return str(value)


def _csv_cell(value: Any) -> str:
    if _missing(value):
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _json_value(value: Any) -> Any:
    if _missing(value):
        return None
    if isinstance(value, float) and math.isinf(value):
        return None  # JSON has no infinity
    return value


def format_table(
    columns: Sequence[Column],
    rows: Sequence[Mapping[str, Any]],
    fmt: str = "md",
    digits: int = DIGITS,
) -> str:
    """The rows as a table in format ``fmt`` (:data:`FORMATS`), ending with a newline.

    Parameters
    ----------
    columns : sequence of Column
        The columns, in order.
    rows : sequence of mapping
        One mapping per row, by column key; values are None, bool, int, float or str.
    fmt : str
        ``md``, ``csv`` or ``json`` (or an alias, :data:`ALIASES`).
    digits : int
        Significant digits of the floats of a Markdown table.

    Raises
    ------
    ValueError
        An unknown format.

    Examples
    --------
    >>> cols = [Column("name", text=True), Column("rate"), Column("ok")]
    >>> rows = [{"name": "a", "rate": 1 / 3, "ok": True}]
    >>> print(format_table(cols, rows), end="")
    | name |   rate |  ok |
    | ---- | -----: | --: |
    | a    | 0.3333 | yes |
    >>> print(format_table(cols, rows, "csv"), end="")
    name,rate,ok
    a,0.3333333333333333,true
    """
    fmt = table_format(fmt)
    keys = [c.key for c in columns]
    if fmt == "json":
        doc = [{k: _json_value(row[k]) for k in keys} for row in rows]
        return json.dumps(doc, indent=2, allow_nan=False) + "\n"
    if fmt == "csv":
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(keys)
        writer.writerows([_csv_cell(row[k]) for k in keys] for row in rows)
        return buf.getvalue()
    header = [c.title or c.key for c in columns]
    cells = [[_markdown_cell(row[c.key], c, digits) for c in columns] for row in rows]
    widths = [
        max(3, *(len(line[i]) for line in [header, *cells]))
        for i in range(len(columns))
    ]

    def line(items: Sequence[str]) -> str:
        return "| " + " | ".join(items) + " |"

    def aligned(items: Sequence[str]) -> str:
        return line(
            [
                item.ljust(w) if c.text else item.rjust(w)
                for item, w, c in zip(items, widths, columns, strict=True)
            ]
        )

    rule = [
        "-" * w if c.text else "-" * (w - 1) + ":"
        for w, c in zip(widths, columns, strict=True)
    ]
    out = [aligned(header), line(rule), *(aligned(r) for r in cells)]
    return "\n".join(out) + "\n"
