"""What a run will need, estimated when it is validated, and the bounds that follow.

A run's memory grows with what it keeps for its whole length or sizes by its
parameters: the record (one sample of every vehicle per ``record_every`` periods),
which the metrics then read whole; the range sensors' readings of every sample; a
detector's windows; the broadcast held over the sensing delay; the braking barrier's
stop of every vehicle, planned each period; the loop metrics' buffers. The loader
estimates each of them from the scenario (:func:`estimate`) and refuses one that
would not fit (:func:`check_needs`), in one line naming the key that sets the largest
need and the sizes, instead of a run that fills the machine's memory and is killed.

The bounds follow the machine: the memory a run may need is :data:`MEMORY_SHARE` of
the memory of this machine (or of the control group the process runs in, if that is
less); a record larger than :data:`SPILL_BYTES` streams to files in the temporary
directory (:mod:`sandbox.run.recorder`), which must have room for it. A scenario
valid on one machine may therefore be refused on a smaller one; the message says how
much it needs and how much there is.

The sizes of the loop's arrays are copied here from the stages that own them (the
scenario is validated below them); ``tests/test_hostile_limits.py`` compares them
with those stages' own.
"""

from __future__ import annotations

import functools
import math
import os
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: The share of the machine's memory a run may need.
MEMORY_SHARE = 0.5
#: Bytes of one vehicle's part of a recorded sample (pose 3, cmd 2, chi 2, slot 2,
#: target 2 float64; mode int8; failed bool) and of the sample's own part (t, the
#: reference point) (:mod:`sandbox.run.recorder`).
RECORD_VEHICLE_BYTES = 8 * 11 + 2
RECORD_SAMPLE_BYTES = 8 * 3
#: How much more memory the metrics take while they read the record whole, as a
#: multiple of the record (measured: 0.9-1.2 for 4-40 vehicles).
METRICS_FACTOR = 1.0
#: Above this size [bytes] the record streams to disk (:mod:`sandbox.run.recorder`).
SPILL_BYTES = 64 * 2**20
#: Bytes of one range reading kept for every sample (float32).
RANGE_BYTES = 4
#: Periods of the loop metrics' buffers, and the most vehicles whose every pair is
#: buffered (:mod:`sandbox.loop.tally`, :data:`sandbox.run.metrics.ALL_PAIRS_MAX`).
TALLY_PERIODS = 64
ALL_PAIRS_MAX = 64
#: Bytes a detector's window keeps per vehicle and period: the GLR's observation
#: time, its three sums and a flag (:mod:`sandbox.behaviour.glr`).
WINDOW_BYTES = 8 + 3 * 8 + 1
#: Bytes the GLR's noise window keeps per vehicle and period (three innovations).
NOISE_WINDOW_BYTES = 3 * 8
#: Bytes one period of the broadcast holds per vehicle over the delay (a pose and
#: its copy as received).
DELAY_BYTES = 2 * 3 * 8
#: Arrays of one vehicle's braking, planned each period over the periods of its stop
#: (:mod:`sandbox.behaviour.safety.braking`).
BRAKING_ARRAYS = 12


@dataclass(frozen=True)
class Need:
    """One thing a run keeps, its size, and the key that sets it.

    Attributes
    ----------
    key : str
        The field path that sets it (named in a refusal).
    what : str
        What it is, in words (``the record of 1e+09 samples of 2 vehicles``).
    memory : float
        Its memory [bytes].
    advice : str
        What makes it smaller.
    disk : float
        Bytes it streams to the temporary directory instead of memory.
    """

    key: str
    what: str
    memory: float
    advice: str
    disk: float = 0.0


@functools.cache
def physical_memory() -> float | None:
    """The machine's memory [bytes], or its control group's limit if that is less.

    None where neither can be read (then memory is not bounded).
    """
    try:
        total = float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        total = math.inf
    for path in (
        "/sys/fs/cgroup/memory.max",
        "/sys/fs/cgroup/memory/memory.limit_in_bytes",
    ):
        try:
            text = Path(path).read_text(encoding="ascii").strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, float(text))
    return None if math.isinf(total) or total <= 0 else total


def free_disk(directory: str | None = None) -> tuple[str, float | None]:
    """The temporary directory a record spills to, and its free space [bytes]."""
    where = directory or tempfile.gettempdir()
    try:
        return where, float(shutil.disk_usage(where).free)
    except OSError:
        return where, None


def size_text(size: float) -> str:
    """A size in bytes as ``12.3 GB`` (decimal units).

    >>> size_text(2.04e11)
    '204 GB'
    """
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if size >= scale:
            return f"{size / scale:.3g} {unit}"
    return f"{size:.0f} bytes"


def estimate(
    duration: float,
    dt: float,
    record_every: int,
    vehicles: Sequence[Any],
    *,
    ranges: Sequence[Any] = (),
    sensing: Any = None,
    detection: Any = None,
    safety: Any = None,
) -> list[Need]:
    """The needs of a run of one world, largest first.

    Parameters
    ----------
    duration, dt : float [s]
        The run's length and control period.
    record_every : int
        Periods between two recorded samples.
    vehicles : sequence of VehicleSpec
        The vehicles (their ``v1_max`` and ``max_accel`` size the braking barrier).
    ranges : sequence of RangeSpec or None
        Each vehicle's range sensor (None: none).
    sensing, detection, safety : optional
        The ``sensing:``, ``detection:`` and ``safety:`` sections.
    """
    n = max(len(vehicles), 1)
    steps = math.ceil(duration / dt - 1e-9)
    samples = steps // record_every + 1
    out: list[Need] = []
    record = samples * (n * RECORD_VEHICLE_BYTES + RECORD_SAMPLE_BYTES)
    out.append(
        Need(
            "duration",
            f"the record of {samples:.3g} samples of {n} vehicle"
            f"{'s' if n != 1 else ''} and its metrics",
            record * (1.0 + METRICS_FACTOR),
            "a shorter duration, a longer dt or a larger record_every",
            disk=record if record > SPILL_BYTES else 0.0,
        )
    )
    beams = sum(r.beams for r in ranges if r is not None)
    if beams:
        out.append(
            Need(
                "sensors.range.beams",
                f"the range readings of {samples:.3g} samples of {beams} beams",
                samples * beams * RANGE_BYTES,
                "fewer beams, a shorter duration or a larger record_every",
            )
        )
    if detection is not None:
        out.extend(_detector_needs(detection, dt, n))
    if sensing is not None and sensing.delay > 0:
        held = min(round(sensing.delay / dt), steps) + 1
        out.append(
            Need(
                "sensing.delay",
                f"the broadcast held over {held} periods",
                held * n * DELAY_BYTES,
                "a shorter delay",
            )
        )
    if safety is not None and safety.params.get("barrier") == "braking":
        out.extend(_braking_needs(vehicles, dt, n))
    pairs = n * (n - 1) // 2 if n <= ALL_PAIRS_MAX else 0
    out.append(
        Need(
            "vehicles",
            "the loop metrics' buffers",
            TALLY_PERIODS * (pairs + 6 * n) * 8,
            "fewer vehicles",
        )
    )
    return sorted(out, key=lambda need: -need.memory)


def _detector_needs(detection: Any, dt: float, n: int) -> list[Need]:
    """The windows a detector keeps for every vehicle (the GLR's are arrays)."""
    params = detection.params
    out = []
    if detection.method == "glr":
        for key, per in (
            ("window", WINDOW_BYTES),
            ("noise_window", NOISE_WINDOW_BYTES),
        ):
            span = params.get(key)
            if isinstance(span, int | float) and span > 0:
                periods = round(span / dt) + 1
                out.append(
                    Need(
                        f"detection.{key}",
                        f"the detector's {key.replace('_', ' ')} of {periods:.3g} "
                        "periods",
                        n * periods * per,
                        f"a shorter {key}",
                    )
                )
    return out


def _braking_needs(vehicles: Sequence[Any], dt: float, n: int) -> list[Need]:
    """The braking barrier's plan of every vehicle's stop, made each period."""
    periods = 0.0
    for v in vehicles:
        if v.v1_max is not None and v.max_accel is not None and v.max_accel > 0:
            periods = max(periods, math.ceil(v.v1_max / (v.max_accel * dt)) + 3)
    if not periods:
        return []
    return [
        Need(
            "vehicle.max_accel",
            f"the braking barrier's stops of {periods:.3g} periods",
            BRAKING_ARRAYS * n * periods * 8,
            "a larger max_accel or a smaller v1_max (a stop of fewer periods)",
        )
    ]


def check_needs(rd: Any, needs: list[Need], *, memory: float | None = None) -> None:
    """Refuse, in one problem at the key of the largest need, a run that cannot fit.

    Parameters
    ----------
    rd : Reader
        The loader's reader (the problem is recorded there).
    needs : list of Need
        From :func:`estimate`.
    memory : float, optional
        The machine's memory [bytes] (default :func:`physical_memory`).
    """
    machine = physical_memory() if memory is None else memory
    if machine is not None:
        allowed = MEMORY_SHARE * machine
        total = sum(need.memory for need in needs)
        if total > allowed:
            worst = max(needs, key=lambda need: need.memory)
            parts = "; ".join(
                f"{need.what} {size_text(need.memory)}"
                for need in needs[:3]
                if need.memory >= 0.01 * total
            )
            rd.fail(
                worst.key,
                f"the run would need about {size_text(total)} of memory",
                parts,
                f"at most {size_text(allowed)}, {MEMORY_SHARE:.0%} of this machine's "
                f"{size_text(machine)}: {worst.advice}",
            )
            return
    disk = sum(need.disk for need in needs)
    if disk:
        where, free = free_disk()
        if free is not None and disk > free:
            worst = max(needs, key=lambda need: need.disk)
            rd.fail(
                worst.key,
                f"the record would stream {size_text(disk)} to {where}",
                f"{size_text(free)} free there",
                f"a record that fits: {worst.advice} (or TMPDIR on a larger disk)",
            )
