"""A ``run.npz`` read back: every member checked before anything draws it.

:func:`read_checked` is what :meth:`Run.load_npz <sandbox.run.record.Run.load_npz>`
(and so ``sandbox view``, ``render``, ``plot`` and ``sweep view``) reads a run with. It
refuses, with a :class:`RunFileError` naming the member, a file that is not a run
written by :meth:`Run.save_npz <sandbox.run.record.Run.save_npz>`:

- the archive: missing or unknown members, sizes that would inflate beyond what
  DEFLATE can produce from the compressed size (a compression bomb), headers that do
  not match the data, Python objects; all checked before anything is inflated;
- the arrays: shapes against the samples ``T``, vehicles ``n`` and beams ``B``, dtypes;
  and their values (:func:`check_values`): times finite and increasing, no infinity
  and no magnitude beyond :data:`LIMIT` (NaN is allowed where a run records it: no
  slot, no reference, a diverged state), modes among the known codes, diameters
  positive;
- the metadata (:func:`check_meta`): names, colours, leader, status, the collision
  events, and each entry of ``info`` that the metrics, the pictures and the replay
  read (:data:`INFO`), to its items (``meta.info.failures[0].at: not a number``).

A diverged run's last sample holds the state that diverged: its values are not
bounded. Entries of ``info`` not listed are kept unread.
"""

from __future__ import annotations

import json
import math
import unicodedata
import zipfile
from collections.abc import Callable
from typing import Any

import numpy as np

from sandbox.run.codes import MODE_NAMES, STATUS_DIVERGED, STATUSES

__all__ = [
    "INFO",
    "LIMIT",
    "MAX_INFLATION",
    "MEMBERS",
    "META_MAX_BYTES",
    "OPTIONAL",
    "RunFileError",
    "check_meta",
    "check_values",
    "read_checked",
]


class RunFileError(ValueError):
    """A ``run.npz`` that is not a run written by ``Run.save_npz``; names the member."""


#: Members of ``run.npz``: name -> (dtype kind, shape in terms of T samples and n
#: vehicles).
MEMBERS: dict[str, tuple[str, tuple[str | int, ...]]] = {
    "t": ("f", ("T",)),
    "pose": ("f", ("T", "n", 3)),
    "cmd": ("f", ("T", "n", 2)),
    "chi": ("f", ("T", "n", 2)),
    "slot": ("f", ("T", "n", 2)),
    "target": ("f", ("T", "n", 2)),
    "mode": ("i", ("T", "n")),
    "failed": ("b", ("T", "n")),
    "reference": ("f", ("T", 2)),
    "diameter": ("f", ("n",)),
}
#: Members of a run with range sensors (``B``: the most beams of a vehicle).
OPTIONAL: dict[str, tuple[str, tuple[str | int, ...]]] = {
    "ranges": ("f", ("T", "n", "B")),
    "beam_angles": ("f", ("n", "B")),
}
#: Largest metadata string of a run.npz [bytes] (names, colours, events, info).
META_MAX_BYTES = 256 * 2**20
#: DEFLATE inflates at most about 1032 times; a member claiming more is a bomb.
MAX_INFLATION = 1100
#: The largest magnitude of a recorded value [m], [rad], [m/s], [rad/s], [s]: the
#: loader's bound on any number of a scenario.
LIMIT = 1e9
#: The longest name or colour of a vehicle, in characters.
MAX_NAME = 1000


def read_checked(path: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The metadata and arrays of a ``run.npz``, each checked before it is read.

    Raises
    ------
    RunFileError
        Naming the member and what is wrong with it.
    """
    with zipfile.ZipFile(path) as zf:
        infos = {i.filename: i for i in zf.infolist()}
        names = {k[: -len(".npy")] for k in infos if k.endswith(".npy")}
        expected = {*MEMBERS, "meta"}
        members = dict(MEMBERS)
        if names & set(OPTIONAL):  # both or neither
            expected |= set(OPTIONAL)
            members.update(OPTIONAL)
        if "steer" in names:  # a run with cars
            expected.add("steer")
            members["steer"] = ("f", ("T", "n"))
        missing = sorted(expected - names)
        extra = sorted(set(infos) - {f"{k}.npy" for k in expected})
        if missing or extra:
            what = f"no {', '.join(missing)}" if missing else f"unknown {extra[0]!r}"
            raise RunFileError(f"not the members of a run ({what})")
        headers = {}
        for key in sorted(expected):
            info = infos[f"{key}.npy"]
            if info.file_size > MAX_INFLATION * max(info.compress_size, 1) + 4096:
                raise RunFileError(
                    f"{key}: claims {info.file_size:,} bytes from "
                    f"{info.compress_size:,} compressed (a compression bomb)"
                )
            with zf.open(info) as fh:
                try:
                    version = np.lib.format.read_magic(fh)
                    read_header = (
                        np.lib.format.read_array_header_1_0
                        if version == (1, 0)
                        else np.lib.format.read_array_header_2_0
                    )
                    shape, _, dtype = read_header(fh, max_header_size=10000)
                except (ValueError, SyntaxError, EOFError, TypeError) as exc:
                    raise RunFileError(f"{key}: not an array ({exc})") from None
                header = fh.tell() if fh.seekable() else None
            if dtype.hasobject:
                raise RunFileError(f"{key}: holds Python objects")
            size = int(np.prod(shape, dtype=object)) * dtype.itemsize
            if header is not None and size != info.file_size - header:
                raise RunFileError(
                    f"{key}: its header claims {size:,} bytes, it holds "
                    f"{info.file_size - header:,}"
                )
            headers[key] = (shape, dtype)
        m_shape, m_dtype = headers["meta"]
        if m_shape != () or m_dtype.kind != "U":
            raise RunFileError("meta: not a text")
        if infos["meta.npy"].file_size > META_MAX_BYTES:
            raise RunFileError("meta: too large")
        t_shape = headers["t"][0]
        d_shape = headers["diameter"][0]
        if len(t_shape) != 1 or len(d_shape) != 1:
            raise RunFileError("t and diameter: not one-dimensional")
        dims = {"T": t_shape[0], "n": d_shape[0]}
        if "beam_angles" in headers:
            b_shape = headers["beam_angles"][0]
            dims["B"] = b_shape[-1] if len(b_shape) == 2 else -1
        if dims["T"] < 1:
            raise RunFileError("no recorded samples")
        if dims["n"] < 1:
            raise RunFileError("no vehicles")
        for key, (kind, form) in members.items():
            shape, dtype = headers[key]
            want = tuple(dims[d] if isinstance(d, str) else d for d in form)
            if tuple(shape) != want:
                raise RunFileError(f"{key}: shape {tuple(shape)}, expected {want}")
            if dtype.kind != kind:
                raise RunFileError(f"{key}: dtype {dtype}, expected kind {kind!r}")
        with zf.open("meta.npy") as fh:
            text = str(np.lib.format.read_array(fh, allow_pickle=False))
        arrays = {}
        for key in members:
            with zf.open(f"{key}.npy") as fh:
                arrays[key] = np.lib.format.read_array(fh, allow_pickle=False)
    try:
        meta = json.loads(text)
    except (ValueError, RecursionError):
        raise RunFileError("meta: not JSON") from None
    check_meta(meta, dims["n"])
    check_values(arrays, meta["status"])
    return meta, arrays


# ------------------------------------------------------------------------ the values
#: The members whose values are bounded by :data:`LIMIT` (NaN allowed).
BOUNDED = ("pose", "cmd", "chi", "slot", "target", "reference", "ranges")


def check_values(arrays: dict[str, np.ndarray], status: str) -> None:
    """Check the values of a run's arrays (see the module docstring).

    Raises
    ------
    RunFileError
        Naming the member, and the first sample or vehicle at fault.
    """
    t = arrays["t"]
    if not np.isfinite(t).all() or np.abs(t).max() > LIMIT:
        k = int(np.argmax(~np.isfinite(t) | (np.abs(np.nan_to_num(t)) > LIMIT)))
        raise RunFileError(f"t: sample {k} is {float(t[k]):g}, not a time [s]")
    if len(t) > 1 and not (np.diff(t) > 0).all():
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise RunFileError(
            f"t: not increasing (sample {k} at {t[k]:g} s after {t[k - 1]:g} s)"
        )
    # a diverged run's last sample holds the state that diverged: not bounded
    rows = slice(None, -1) if status == STATUS_DIVERGED else slice(None)
    for key in BOUNDED:
        if key not in arrays:
            continue
        values = arrays[key][rows]
        with np.errstate(invalid="ignore"):
            bad = np.isinf(values) | (np.abs(values) > LIMIT)
        if bad.any():
            where = np.unravel_index(int(np.argmax(bad)), bad.shape)
            raise RunFileError(
                f"{key}: {float(values[where]):g} at {list(map(int, where))}, beyond "
                f"{LIMIT:g} (a recorded value is finite or NaN)"
            )
    if "ranges" in arrays and (np.nan_to_num(arrays["ranges"], nan=0.0) < 0).any():
        raise RunFileError("ranges: a negative reading")
    if "beam_angles" in arrays:
        angles = arrays["beam_angles"]
        if not (np.isfinite(angles) & (np.abs(angles) <= 2 * math.pi + 1e-9)).all():
            raise RunFileError("beam_angles: an angle not in [-2 pi, 2 pi] [rad]")
    mode = arrays["mode"]
    if mode.size and (mode.min() < 0 or mode.max() >= len(MODE_NAMES)):
        raise RunFileError(
            f"mode: code {int(mode.min() if mode.min() < 0 else mode.max())}, "
            f"expected 0 to {len(MODE_NAMES) - 1} ({', '.join(MODE_NAMES)})"
        )
    d = arrays["diameter"]
    if not (np.isfinite(d) & (d > 0) & (d <= LIMIT)).all():
        i = int(np.argmax(~(np.isfinite(d) & (d > 0) & (d <= LIMIT))))
        raise RunFileError(
            f"diameter: vehicle {i} has {float(d[i]):g}, expected > 0 [m]"
        )


# ---------------------------------------------------------------------- the metadata
def check_meta(meta: Any, n: int) -> None:
    """Check the metadata of a run against its ``n`` vehicles.

    Raises
    ------
    RunFileError
        Naming the entry (``meta.info.failures[0]: ...``).
    """
    if not isinstance(meta, dict):
        raise RunFileError("meta: not a mapping")
    for key in ("names", "colors"):
        value = meta.get(key)
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise RunFileError(f"meta: {key} is not a list of texts")
        if len(value) != n:
            raise RunFileError(f"meta: {len(value)} {key} for {n} vehicles")
        for i, text in enumerate(value):
            if not text or len(text) > MAX_NAME or _unprintable(text):
                raise RunFileError(
                    f"meta.{key}[{i}]: {text[:40]!r} is not a name (1 to {MAX_NAME} "
                    "printable characters)"
                )
    if len(set(meta["names"])) != n:
        raise RunFileError("meta.names: a name is given twice")
    leader = meta.get("leader")
    if isinstance(leader, bool) or not isinstance(leader, int) or not -1 <= leader < n:
        raise RunFileError(f"meta: leader {leader!r} is not a vehicle index or -1")
    if meta.get("status") not in STATUSES:
        raise RunFileError(f"meta: unknown status {meta.get('status')!r}")
    if not isinstance(meta.get("info"), dict):
        raise RunFileError("meta: info is not a mapping")
    events = meta.get("events")
    if not isinstance(events, list):
        raise RunFileError("meta: events is not a list")
    for row in events:
        ok = (
            isinstance(row, list)
            and len(row) == 7
            and _is_number(row[0])
            and isinstance(row[1], str)
            and isinstance(row[2], str)
            and row[3] in ("vehicle_vehicle", "vehicle_obstacle")
            and (row[4] is None or _is_number(row[4]))
            and (row[5] is None or isinstance(row[5], bool))
            and _is_number(row[6])
        )
        if not ok:
            raise RunFileError(
                f"meta: an event is not [t, a, b, kind, ...]: {row!r:.60}"
            )
    names = set(meta["names"])
    for key, check in INFO.items():
        if key in meta["info"]:
            check(meta["info"][key], f"meta.info.{key}", names)


def _unprintable(text: str) -> bool:
    """Whether ``text`` holds a control character (line breaks included)."""
    return any(unicodedata.category(c) in ("Cc", "Zl", "Zp") for c in text)


def _is_number(x: Any) -> bool:
    """A finite int or float within :data:`LIMIT` (not a bool)."""
    return (
        isinstance(x, int | float)
        and not isinstance(x, bool)
        and math.isfinite(x)
        and abs(x) <= LIMIT
    )


# What one entry of ``info`` must be: check(value, where, names) raises RunFileError.
Check = Callable[[Any, str, set[str]], None]


def _fail(where: str, value: Any, expected: str) -> RunFileError:
    return RunFileError(f"{where}: {_describe(value)}, expected {expected}")


def _describe(value: Any) -> str:
    text = repr(value)
    return f"got {text[:40]}{'...' if len(text) > 40 else ''}"


def number(low: float = -LIMIT, optional: bool = False) -> Check:
    """A finite number >= ``low`` (None too with ``optional``)."""

    def check(value: Any, where: str, names: set[str]) -> None:
        if optional and value is None:
            return
        if not _is_number(value) or value < low:
            raise _fail(where, value, f"a number >= {low:g}")

    return check


def whole(low: int = 0, optional: bool = False) -> Check:
    """A whole number >= ``low`` (None too with ``optional``)."""

    def check(value: Any, where: str, names: set[str]) -> None:
        if optional and value is None:
            return
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise _fail(where, value, f"a whole number >= {low}")

    return check


def text(optional: bool = False) -> Check:
    """A text (None too with ``optional``)."""

    def check(value: Any, where: str, names: set[str]) -> None:
        if not (isinstance(value, str) or (optional and value is None)):
            raise _fail(where, value, "a text")

    return check


def flag(value: Any, where: str, names: set[str]) -> None:
    """True or false."""
    if not isinstance(value, bool):
        raise _fail(where, value, "true or false")


def vehicle(optional: bool = False) -> Check:
    """The name of a vehicle of the run (None too with ``optional``)."""

    def check(value: Any, where: str, names: set[str]) -> None:
        if optional and value is None:
            return
        if not isinstance(value, str) or value not in names:
            raise _fail(where, value, "the name of a vehicle of the run")

    return check


def point(optional: bool = False) -> Check:
    """Two finite numbers ``[x1, x2]`` [m] (None too with ``optional``)."""

    def check(value: Any, where: str, names: set[str]) -> None:
        if optional and value is None:
            return
        if not (
            isinstance(value, list) and len(value) == 2 and all(map(_is_number, value))
        ):
            raise _fail(where, value, "a point [x1, x2] of finite numbers")

    return check


def items(item: Check) -> Check:
    """A list, each item checked."""

    def check(value: Any, where: str, names: set[str]) -> None:
        if not isinstance(value, list):
            raise _fail(where, value, "a list")
        for k, x in enumerate(value):
            item(x, f"{where}[{k}]", names)

    return check


def row(*columns: Check) -> Check:
    """A list of exactly these columns, in order."""

    def check(value: Any, where: str, names: set[str]) -> None:
        if not isinstance(value, list) or len(value) != len(columns):
            raise _fail(where, value, f"a list of {len(columns)} values")
        for k, (x, column) in enumerate(zip(value, columns, strict=True)):
            column(x, f"{where}[{k}]", names)

    return check


def fields(
    required: dict[str, Check], optional: dict[str, Check] | None = None
) -> Check:
    """A mapping with the ``required`` keys and maybe the ``optional`` ones, checked.

    Other keys are left unread.
    """

    def check(value: Any, where: str, names: set[str]) -> None:
        if not isinstance(value, dict):
            raise _fail(where, value, "a mapping")
        for key, field in required.items():
            if key not in value:
                raise RunFileError(f"{where}: no {key}")
            field(value[key], f"{where}.{key}", names)
        for key, field in (optional or {}).items():
            if key in value:
                field(value[key], f"{where}.{key}", names)

    return check


def by_name(item: Check, vehicles: bool = True) -> Check:
    """A mapping of vehicle names (or of any texts) to checked values."""

    def check(value: Any, where: str, names: set[str]) -> None:
        if not isinstance(value, dict):
            raise _fail(where, value, "a mapping")
        for key, x in value.items():
            if vehicles and key not in names:
                raise _fail(where, key, "the names of vehicles of the run as keys")
            item(x, f"{where}.{key}", names)

    return check


def per_vehicle(value: Any, where: str, names: set[str]) -> None:
    """One finite number per vehicle (a loop metric)."""
    if not isinstance(value, list) or len(value) != len(names):
        raise _fail(where, value, f"a list of {len(names)} numbers (one per vehicle)")
    for k, x in enumerate(value):
        number()(x, f"{where}[{k}]", names)


def obstacle(value: Any, where: str, names: set[str]) -> None:
    """An obstacle as drawn: a circle, or a polygon of at least two points."""
    fields({"type": text()}, {"name": text()})(value, where, names)
    if value["type"] == "circle":
        fields({"center": point(), "radius": number(0.0)})(value, where, names)
    elif value["type"] == "polygon":
        fields({"points": items(point())})(value, where, names)
        if len(value["points"]) < 2:
            raise _fail(f"{where}.points", value["points"], "at least two points")
    else:
        raise _fail(f"{where}.type", value["type"], "circle or polygon")


#: The entries of ``Run.info`` read by the metrics, the figures, the GIF and the
#: replay, and what each must be. Others are kept as they are, unread.
INFO: dict[str, Check] = {
    "scenario_name": text(),
    "law": text(optional=True),
    "recovery": fields(
        {},
        {
            "strategy": text(),
            "beta": number(optional=True),
            "R": number(optional=True),
            "r": number(optional=True),
            "leader_avoids": flag,
            "target_derivatives": text(),
        },
    ),
    "obstacles": items(obstacle),
    "failures": items(
        fields(
            {
                "vehicle": vehicle(),
                "kind": text(),
                "at": number(),
                "until": number(optional=True),
            }
        )
    ),
    "dt": number(1e-12),
    "record_every": whole(1),
    "steps": whole(0),
    "reference_path": items(point()),
    "reassignments": items(
        fields({"t": number(), "assignment": by_name(whole(0, optional=True))})
    ),
    "leader_changes": items(
        fields(
            {"t": number()},
            {
                "from": vehicle(optional=True),
                "to": vehicle(optional=True),
                "mode": text(),
            },
        )
    ),
    "slots": by_name(items(row(number(), whole(0, optional=True)))),
    "failed_at": by_name(number()),
    "detection": fields(
        {},
        {
            "method": text(optional=True),
            "events": items(
                fields(
                    {"vehicle": vehicle(), "t": number()},
                    {"kind": text(optional=True), "cleared": number(optional=True)},
                )
            ),
        },
    ),
    "loop_metrics": fields(
        {},
        {
            "effort_v1": per_vehicle,
            "effort_v2": per_vehicle,
            "peak_v1": per_vehicle,
            "min_distance": number(optional=True),
            "motor": fields({}),
        },
    ),
    "platoon_events": items(
        fields(
            {"t": number()},
            {
                "platoons": by_name(items(vehicle()), vehicles=False),
                "offsets": by_name(point(optional=True)),  # None: no slot
            },
        )
    ),
    "formation_timeline": by_name(items(row(number(), text(), point(optional=True)))),
    "diverged": fields(
        {}, {"t": number(), "vehicle": text(optional=True), "reason": text()}
    ),
    "error": fields({}, {"t": number(), "plugin": text(), "message": text()}),
    "interrupted": fields({}, {"t": number()}),
    "safety": fields({}, {"filter": text()}),
}
