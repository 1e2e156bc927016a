"""What a sweep runs: a base scenario, grid and zipped paths, seeds, fixed overrides.

A sweep is the Cartesian product of its ``grid`` paths (each with a list of values),
times one column of ``zip`` paths varied together (lists of equal length), times the
``seeds`` (``A:B`` is ``range(A, B)``); every grid point runs on the same seeds (common
random numbers). Each run is the scenario ``sandbox run BASE --set <fixed> --set
<its values> --set seed=<its seed>`` would simulate.

A sweep file holds the same in YAML::

    base: ../paper/fig13_discontinuous_beta1.yaml   # relative to the sweep file
    set: {duration: 15}                            # fixed overrides (optional)
    grid:
      recovery.beta: [1, 2, 5]
    zip:
      vehicles[1].offset: [[-2, 1], [-1.4, 0.8]]
      vehicles[2].offset: [[-2, -1], [-1.4, -0.8]]
    seeds: 0:200

Run ids are the first 16 hex digits of the SHA-256 of the run's values and seed as
canonical JSON (sorted keys): the same on every machine and invocation, whatever the
order of keys in the files.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from sandbox.errors import SandboxError

SWEEP_KEYS = ("base", "set", "grid", "zip", "seeds")
#: Most runs a sweep may have unless ``--max-runs`` allows more (its tasks are counted
#: before any is built).
MAX_RUNS = 100_000
_PATH = re.compile(
    r"^[A-Za-z_][A-Za-z0-9_]*(\[\d+\])*(\.[A-Za-z_][A-Za-z0-9_]*(\[\d+\])*)*$"
)


class SweepError(SandboxError):
    """A sweep specification or results directory that cannot be used."""


@dataclass(frozen=True)
class Axis:
    """One varied path: its text as written, and its values (text and parsed)."""

    path: str
    texts: tuple[str, ...]
    values: tuple[Any, ...]


@dataclass(frozen=True)
class Task:
    """One run of a sweep: its id, the values of the varied paths, and its seed."""

    run_id: str
    point: int
    values: tuple[tuple[str, str], ...]
    seed: int

    def overrides(self, fixed: tuple[str, ...]) -> list[str]:
        """The ``--set`` assignments that give this run's scenario."""
        return [*fixed, *(f"{p}={t}" for p, t in self.values), f"seed={self.seed}"]


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep."""

    base: Path
    grid: tuple[Axis, ...] = ()
    zipped: tuple[Axis, ...] = ()
    seeds: range = range(0, 1)
    fixed: tuple[str, ...] = ()
    source: str = ""
    paths: tuple[str, ...] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "paths", tuple(a.path for a in (*self.grid, *self.zipped))
        )

    def n_points(self) -> int:
        """The number of grid points, by arithmetic (nothing is built)."""
        n = math.prod(len(a.values) for a in self.grid)
        return n * (len(self.zipped[0].values) if self.zipped else 1)

    def count(self) -> int:
        """The number of runs, by arithmetic (nothing is built)."""
        return self.n_points() * (self.seeds.stop - self.seeds.start)

    def check_size(self, max_runs: int = MAX_RUNS) -> None:
        """Refuse a sweep of more than ``max_runs`` runs, before anything is built.

        Raises
        ------
        SweepError
            The sweep has more runs than ``max_runs``.
        """
        runs = self.count()
        if runs > max_runs:
            points, seeds = self.n_points(), self.seeds.stop - self.seeds.start
            raise SweepError(
                f"{self.source}: {runs:,} runs ({points:,} grid point"
                f"{'s' if points != 1 else ''} x {seeds:,} seed"
                f"{'s' if seeds != 1 else ''}); at most {max_runs:,} (fewer values "
                "or seeds, or a larger --max-runs)"
            )

    def iter_points(self) -> Iterator[tuple[tuple[str, str, Any], ...]]:
        """Every grid point, one at a time: ``(path, text, value)`` per varied path."""
        grids = [list(zip(a.texts, a.values, strict=True)) for a in self.grid]
        zips: list[tuple[tuple[str, str, Any], ...]] = [()]
        if self.zipped:
            n = len(self.zipped[0].values)
            zips = [
                tuple((a.path, a.texts[i], a.values[i]) for a in self.zipped)
                for i in range(n)
            ]
        for combo in itertools.product(*grids):
            head = tuple(
                (a.path, t, v) for a, (t, v) in zip(self.grid, combo, strict=True)
            )
            for z in zips:
                yield head + tuple(z)

    def points(self) -> list[tuple[tuple[str, str, Any], ...]]:
        """Every grid point: ``(path, text, value)`` for each varied path."""
        return list(self.iter_points())

    def iter_tasks(self) -> Iterator[Task]:
        """Every run, one at a time, grid point by grid point, seeds in order."""
        for k, point in enumerate(self.iter_points()):
            values = tuple((p, t) for p, t, _ in point)
            for seed in self.seeds:
                yield Task(run_id(point, seed), k, values, seed)

    def tasks(self) -> list[Task]:
        """Every run, grid point by grid point, seeds in order."""
        return list(self.iter_tasks())


def run_id(point: tuple[tuple[str, str, Any], ...], seed: int) -> str:
    """The stable id of a run: a hash of its values (parsed) and seed."""
    doc = {"seed": seed, "values": {p: v for p, _, v in point}}
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def split_values(text: str) -> list[str]:
    """Split ``v1,v2,...`` at the commas outside brackets, braces and quotes.

    >>> split_values("1,2.5,[0, 1],{a: 1, b: 2},'x,y'")
    ['1', '2.5', '[0, 1]', '{a: 1, b: 2}', "'x,y'"]
    """
    out, depth, quote, start = [], 0, "", 0
    for i, c in enumerate(text):
        if quote:
            quote = "" if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c in "[{":
            depth += 1
        elif c in "]}":
            depth -= 1
        elif c == "," and depth == 0:
            out.append(text[start:i].strip())
            start = i + 1
    out.append(text[start:].strip())
    return out


def _parse_value(text: str, where: str) -> Any:
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        raise SweepError(f"{where}: {text!r} is not a YAML value") from None


def value_text(value: Any) -> str:
    """A value as ``--set`` reads it back: plain strings, else compact JSON."""
    if isinstance(value, str):
        return value
    return json.dumps(value, separators=(",", ":"))


def _check_path(path: str, where: str) -> str:
    path = path.strip()
    if not _PATH.match(path):
        raise SweepError(
            f"{where}: {path!r} names no field (expected a dotted path like "
            "recovery.beta or vehicles[1].pose)"
        )
    return path


def axis_from_option(item: str, where: str) -> Axis:
    """An axis from ``PATH=v1,v2,...`` (the ``--grid`` / ``--zip`` syntax)."""
    path, sep, raw = item.partition("=")
    if not sep or not raw.strip():
        raise SweepError(
            f"{where} {item}: expected PATH=v1,v2,... (e.g. recovery.beta=1,2,5)"
        )
    path = _check_path(path, f"{where} {item}")
    texts = split_values(raw)
    if any(t == "" for t in texts):
        raise SweepError(f"{where} {item}: an empty value (expected v1,v2,...)")
    values = tuple(_parse_value(t, f"{where} {item}") for t in texts)
    return Axis(path, tuple(texts), values)


def axis_from_list(path: str, values: Any, where: str) -> Axis:
    """An axis from a sweep file's ``path: [v1, v2, ...]``."""
    path = _check_path(str(path), where)
    if not isinstance(values, list) or not values:
        raise SweepError(f"{where}.{path}: expected a non-empty list of values")
    return Axis(path, tuple(value_text(v) for v in values), tuple(values))


def normal_value(text: str) -> Any:
    """The value ``--set PATH=text`` gives, in a form equal for equal values.

    ``1``, ``01``, ``1.0`` and ``1e0`` are one number, ``[1, 2]`` and ``[1.0, 2]`` one
    list; booleans stay apart from numbers.

    >>> normal_value("01") == normal_value("1.0") == normal_value("1e0")
    True
    """
    from sandbox.scenario.yamlfile import YAMLLoader

    try:
        value = yaml.load(text, Loader=YAMLLoader)  # noqa: S506 (a SafeLoader)
    except (yaml.YAMLError, ValueError, RecursionError):
        return ("text", text)
    return _normal(value)


def _normal(value: Any) -> Any:
    if isinstance(value, bool) or value is None:
        return ("const", value)
    if isinstance(value, int | float):
        return ("number", value)  # 1 == 1.0, and so are their hashes
    if isinstance(value, str):
        return ("text", value)
    if isinstance(value, list | tuple):
        return ("list", tuple(_normal(v) for v in value))
    if isinstance(value, Mapping):
        items = sorted((str(k), _normal(v)) for k, v in value.items())
        return ("map", tuple(items))
    return ("other", str(value))


def _check_repeats(texts: tuple[str, ...] | list[str], where: str) -> None:
    """Refuse a value given twice (after normalising: ``1``, ``01``, ``1.0``)."""
    first: dict[Any, str] = {}
    for text in texts:
        key = normal_value(text)
        if key in first:
            same = "again" if first[key] == text else f"the same value as {first[key]}"
            raise SweepError(
                f"{where}: {text} is {same} (each value once: a repeated value "
                "would repeat its runs and count them twice)"
            )
        first[key] = text


def parse_seeds(text: Any, where: str) -> range:
    """``A:B`` (seeds A to B-1, as ``range``), ``[A, B]`` or a single seed ``A``."""
    if isinstance(text, list) and len(text) == 2:
        a, b = text
    elif isinstance(text, int) and not isinstance(text, bool):
        a, b = text, text + 1
    else:
        a, sep, b = str(text).partition(":")
        if not sep:
            a, b = a, None
    try:
        a = int(a)
        b = a + 1 if b is None else int(b)
    except (TypeError, ValueError):
        raise SweepError(
            f"{where}: {text!r} is not a seed range (expected A:B, e.g. 0:100)"
        ) from None
    if a < 0 or b <= a:
        raise SweepError(
            f"{where}: {text!r} is an empty or negative range (expected 0 <= A < B)"
        )
    return range(a, b)


def _check_axes(grid: list[Axis], zipped: list[Axis], source: str = "") -> None:
    seen: set[str] = set()
    for a in [*grid, *zipped]:
        if a.path in seen:
            raise SweepError(f"{a.path}: varied twice (once per path)")
        seen.add(a.path)
    if zipped and len({len(a.values) for a in zipped}) > 1:
        sizes = ", ".join(f"{a.path}: {len(a.values)}" for a in zipped)
        raise SweepError(f"zip: the lists differ in length ({sizes}); expected equal")
    if zipped:
        rows: dict[Any, int] = {}
        for i in range(len(zipped[0].texts)):
            key = tuple(normal_value(a.texts[i]) for a in zipped)
            if key in rows:
                where = f"{source}: zip" if source else "zip"
                raise SweepError(
                    f"{where}: entries {rows[key] + 1} and {i + 1} are the same values "
                    f"of {', '.join(a.path for a in zipped)} (each combination once)"
                )
            rows[key] = i
    if "seed" in seen:
        raise SweepError("seed: vary seeds with --seeds A:B, not as a grid path")


def read_sweep_document(path: str | Path, limited: bool = True) -> Any:
    """The YAML document of a sweep (or scenario) file, within the loader's limits.

    Read by the scenario loader's reader
    (:func:`sandbox.scenario.yamlfile.read_yaml_file`: a regular file, its size, UTF-8,
    aliases that do not expand beyond its limit), with PyYAML's safe loader as
    ``yaml.safe_load`` uses it (so values and run ids are as before). With
    ``limited`` false, aliases may expand without limit (to tell what the document
    is, never to use its values).

    Raises
    ------
    SweepError
        One line naming the file and why it cannot be used.
    """
    from sandbox.errors import ScenarioError
    from sandbox.scenario.yamlfile import read_yaml_file

    try:
        safe = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
        if limited:
            return read_yaml_file(path, loader=safe)
        return read_yaml_file(path, loader=safe, max_nodes=None)
    except ScenarioError as exc:
        raise SweepError(exc.lines[0]) from None


def is_sweep_file(doc: Any) -> bool:
    """Whether a YAML document is a sweep file (it has ``base``)."""
    return isinstance(doc, Mapping) and "base" in doc


def build_spec(
    file: str | Path,
    grid: list[str] | None = None,
    zipped: list[str] | None = None,
    seeds: str | None = None,
    sets: list[str] | None = None,
) -> SweepSpec:
    """The sweep of ``file`` (a scenario or a sweep file) and the command's options.

    Options add to a sweep file's: ``--grid``/``--zip`` of a path the file varies
    replace its values; ``--seeds`` replaces its seeds; ``--set`` adds to its ``set``.
    """
    path = Path(file)
    doc = read_sweep_document(path)
    file_grid: list[Axis] = []
    file_zip: list[Axis] = []
    fixed: list[str] = []
    seed_range = range(0, 1)
    base = path
    if is_sweep_file(doc):
        unknown = [k for k in doc if k not in SWEEP_KEYS]
        if unknown:
            raise SweepError(
                f"{file}: {unknown[0]}: unknown key of a sweep file (expected one of: "
                f"{', '.join(SWEEP_KEYS)})"
            )
        base = Path(os.path.normpath(path.parent / str(doc["base"])))
        if not base.is_file():
            raise SweepError(f"{file}: base: no such scenario file {doc['base']!r}")
        for key, out in (("grid", file_grid), ("zip", file_zip)):
            section = doc.get(key) or {}
            if not isinstance(section, Mapping):
                raise SweepError(f"{file}: {key}: expected a mapping of paths to lists")
            out.extend(
                axis_from_list(p, v, f"{file}: {key}") for p, v in section.items()
            )
        given = doc.get("set") or {}
        if isinstance(given, Mapping):
            fixed = [f"{p}={value_text(v)}" for p, v in given.items()]
        elif isinstance(given, list):
            fixed = [str(x) for x in given]
        else:
            raise SweepError(f"{file}: set: expected a mapping of paths to values")
        if doc.get("seeds") is not None:
            seed_range = parse_seeds(doc["seeds"], f"{file}: seeds")
    cli_grid = [axis_from_option(g, "--grid") for g in grid or []]
    cli_zip = [axis_from_option(z, "--zip") for z in zipped or []]
    over = {a.path for a in cli_grid + cli_zip}
    all_grid = [a for a in file_grid if a.path not in over] + cli_grid
    all_zip = [a for a in file_zip if a.path not in over] + cli_zip
    for a in file_grid:
        if a.path not in over:
            _check_repeats(a.texts, f"{file}: grid.{a.path}")
    for a in cli_grid:
        _check_repeats(a.texts, f"--grid {a.path}={','.join(a.texts)}")
    _check_axes(all_grid, all_zip, str(file))
    if seeds is not None:
        seed_range = parse_seeds(seeds, "--seeds")
    return SweepSpec(
        base=base,
        grid=tuple(all_grid),
        zipped=tuple(all_zip),
        seeds=seed_range,
        fixed=tuple(fixed + list(sets or [])),
        source=str(file),
    )


def iter_chunks(items: list[Any], size: int) -> Iterator[list[Any]]:
    """``items`` in consecutive lists of at most ``size``."""
    for k in range(0, len(items), size):
        yield items[k : k + size]
