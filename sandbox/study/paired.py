"""Two settings compared over the same random starts: the exact McNemar test.

Two settings run over the same seeds give paired outcomes: for each start, did the
run collide (or stay unsettled) under the first setting, and under the second? Rates
with separate Wilson intervals ignore the pairing and overstate the uncertainty of
their difference; the pairs that disagree carry the evidence. With ``b`` the starts
where only the first setting has the outcome and ``c`` those where only the second
has it, the exact McNemar test asks how likely so lopsided a split of the ``b + c``
discordant pairs is if both settings were alike (each discordant pair a fair coin):

    p = min(1, 2 * sum_{k <= min(b, c)} C(b + c, k) / 2^(b + c))

two-sided, exact for any number of pairs (no normal approximation). ``p`` is not
corrected for the number of pairs of settings compared; with many settings, read
small values with that in mind.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Mapping, Sequence
from typing import Any

from sandbox.run.tables import Column, format_table

#: The outcomes compared, as (name, whether a row has it) over rows of ``results.csv``.
OUTCOMES: dict[str, Callable[[Mapping[str, str]], bool]] = {
    "collision": lambda r: int(r["collisions.healthy"] or 0) > 0,
    "unsettled": lambda r: r["converged"] != "true",
}
#: Most settings compared pair by pair in one table (then 28 pairs).
MAX_SETTINGS = 8


def mcnemar_p(b: int, c: int) -> float:
    """Two-sided p-value of the exact McNemar test for ``b`` and ``c`` discordant pairs.

    >>> mcnemar_p(0, 0)
    1.0
    >>> round(mcnemar_p(10, 0), 6)  # ten of ten discordant pairs one way: 2 / 2^10
    0.001953
    >>> mcnemar_p(3, 3)
    1.0
    """
    if b < 0 or c < 0:
        raise ValueError(f"discordant counts must be >= 0, got {b} and {c}")
    n = b + c
    if n == 0:
        return 1.0
    k = min(b, c)
    tail = sum(math.comb(n, i) for i in range(k + 1))
    return min(1.0, 2.0 * tail / 2.0**n)


def paired_rows(
    settings: Sequence[tuple[str, Mapping[Hashable, Mapping[str, str]]]],
) -> list[dict[str, Any]]:
    """McNemar comparisons of every pair of settings over the starts they share.

    Parameters
    ----------
    settings : list of (label, {start: row})
        Each setting's measured rows by start (a seed, or a seed and the values of the
        paths not compared), in the order to compare them.

    Returns
    -------
    list of dict
        Per pair of settings and outcome: ``a``, ``b`` (the labels), ``outcome``,
        ``pairs`` (starts both have), ``a_only`` and ``b_only`` (discordant pairs:
        the outcome under one setting only) and ``p`` (:func:`mcnemar_p`); pairs of
        settings sharing no start are left out.
    """
    out = []
    for i, (label_a, rows_a) in enumerate(settings):
        for label_b, rows_b in settings[i + 1 :]:
            shared = [s for s in rows_a if s in rows_b]
            if not shared:
                continue
            for outcome, has in OUTCOMES.items():
                a_only = sum(1 for s in shared if has(rows_a[s]) and not has(rows_b[s]))
                b_only = sum(1 for s in shared if has(rows_b[s]) and not has(rows_a[s]))
                out.append(
                    {
                        "a": label_a,
                        "b": label_b,
                        "outcome": outcome,
                        "pairs": len(shared),
                        "a_only": a_only,
                        "b_only": b_only,
                        "p": mcnemar_p(a_only, b_only),
                    }
                )
    return out


def sweep_settings(
    rows: Sequence[Mapping[str, str]],
    by: Sequence[str],
    varied: Sequence[str],
    measured: Sequence[str] = ("ok", "diverged"),
) -> list[tuple[str, dict[Hashable, Mapping[str, str]]]]:
    """A sweep's rows as settings (the values of ``by``) of starts (the rest).

    A start is a run's seed with the values of the varied paths not in ``by``, so two
    runs pair only when everything but the compared setting is the same. Rows without
    metrics (``invalid``, ``error``) take no part.
    """
    rest = [p for p in varied if p not in by]
    settings: dict[str, dict[Hashable, Mapping[str, str]]] = {}
    for r in rows:
        if r["status"] not in measured:
            continue
        label = ", ".join(f"{p}={r[p]}" for p in by) or "all"
        start = (r["seed"], *(r[p] for p in rest))
        settings.setdefault(label, {})[start] = r
    return list(settings.items())


#: The heading of the paired comparisons below a Markdown table of rates.
PAIRED_TITLE = (
    "Paired over the same starts (exact McNemar test; a_only / b_only: starts with the "
    "outcome under one setting only; p not corrected for the number of pairs):"
)
#: The columns of the paired comparisons.
PAIRED_COLUMNS = (
    Column("a", text=True),
    Column("b", text=True),
    Column("outcome", text=True),
    Column("pairs"),
    Column("a_only"),
    Column("b_only"),
    Column("p"),
)


def paired_text(
    settings: Sequence[tuple[str, Mapping[Hashable, Mapping[str, str]]]],
    fmt: str = "md",
) -> str | None:
    """The table of :func:`paired_rows`, or None when there is nothing to pair.

    Pairs of settings sharing fewer than two starts are left out (one start is no
    comparison); None also when more than :data:`MAX_SETTINGS` settings would be
    compared.
    """
    if not 2 <= len(settings) <= MAX_SETTINGS:
        return None
    compared = [r for r in paired_rows(settings) if r["pairs"] >= 2]
    if not compared:
        return None
    return format_table(list(PAIRED_COLUMNS), compared, fmt)


def compare_settings(rows: Sequence[Any]) -> list[tuple[str, dict[Hashable, Any]]]:
    """Rows of ``sandbox compare`` as settings over starts.

    A setting is a strategy (with its derivatives, unless ``hold``) and the ``--grid``
    values but the seed; a start is the scenario and its ``seed=`` value, so runs of
    the same file and seed pair. Runs that did not finish (``interrupted``) take no
    part.
    """
    settings: dict[str, dict[Hashable, Any]] = {}
    for r in rows:
        if r.status not in ("ok", "diverged"):
            continue
        tokens = r.setting.split()
        seed = tuple(x for x in tokens if x.startswith("seed="))
        name = r.strategy
        if r.derivatives != "hold":
            name = f"{r.strategy}/{r.derivatives}"
        label = " ".join([name, *(x for x in tokens if not x.startswith("seed="))])
        outcome = {
            "collisions.healthy": str(r.collisions_healthy),
            "converged": "true" if r.converged else "false",
        }
        settings.setdefault(label, {})[(r.scenario, *seed)] = outcome
    return list(settings.items())
