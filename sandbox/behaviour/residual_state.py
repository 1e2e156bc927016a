"""The residual detector's state between periods, and its motor model.

:class:`DetectorState` is what :func:`~sandbox.behaviour.detection.residual` keeps
per vehicle between control periods; :func:`start_state` makes it from the first
observed poses, :func:`shape_history` the observed track history it reads at an
alarm, and :func:`advance_model` moves its motor model by one period (the prediction
of :mod:`sandbox.behaviour.detection`; in C where the compiled path ``controller`` is
on). The ``glr`` detector keeps one too (:mod:`sandbox.behaviour.glr`), and the
kind is read from it (:mod:`sandbox.behaviour.isolation`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from sandbox.behaviour.tracks import TrackHistory
from sandbox.model.kernels import motor_model

if TYPE_CHECKING:
    from sandbox.plugins.contexts import DetectorContext

#: How much of the observed track the crash-or-stop fit reads [s].
SHAPE_HISTORY = 1.0
#: Over how long the speed and the turn rate observed lately are fitted [s]; a
#: braked vehicle's kind is read until its track has been at rest this long.
RECENT_SPEED_WINDOW = 0.2


@dataclass
class DetectorState:
    """What the residual detector keeps between control periods, per vehicle."""

    pose: np.ndarray  # predicted pose since the window's start (n, 3)
    start: np.ndarray  # observed pose at the window's start (n, 3) [m, m, rad]
    vel: np.ndarray  # the model body's velocity (n, 2) [m/s]
    rate: np.ndarray  # the model body's turn rate (n,) [rad/s]
    age: np.ndarray  # periods since the window's start (n,)
    pending: np.ndarray  # the next window starts at the next observation (n,) bool
    travel: np.ndarray  # predicted travel over the window (n,) [m]
    gate: np.ndarray  # periods of the window in or just after contact (n,)
    last_contact: np.ndarray  # time of the last contact (n,) [s]
    g: np.ndarray  # the CUSUM (n,)
    clear: np.ndarray  # the clearing CUSUM of detected vehicles (n,)
    acc: np.ndarray  # normalised residuals summed since g left 0 (n, 3)
    acc_abs: np.ndarray  # their magnitudes summed (n, 3)
    acc_raw: np.ndarray  # raw residuals summed since g left 0 (n, 3)
    acc_obs: np.ndarray  # observed travel since g left 0 (n,) [m]
    acc_pred: np.ndarray  # predicted travel since g left 0 (n,) [m]
    acc_t: np.ndarray  # time since g left 0 (n,) [s]
    acc_rot: np.ndarray  # observed rotation since g left 0 (n,) [rad]
    acc_rot0: np.ndarray  # that of the first window (n,) [rad]
    acc_n: np.ndarray  # windows summed since g left 0 (n,)
    detected: np.ndarray  # latched (n,) bool
    isolating: np.ndarray  # until when the kind is still read (n,) [s]
    kinds: list  # the kind of each latched detection (n,)
    rest: list  # stop or crash, read when the vehicle came to rest; "" (n,)
    history: TrackHistory | None = None  # the last SHAPE_HISTORY s of seen poses


def start_state(ctx: DetectorContext) -> DetectorState:
    """The state of a detector that starts from the poses ``ctx.seen``."""
    n = len(ctx.pos)
    z = np.zeros(n)
    return DetectorState(
        pose=ctx.seen.copy(),
        start=ctx.seen.copy(),
        vel=np.array(ctx.vel, dtype=float),
        rate=z.copy(),
        age=np.zeros(n, dtype=int),
        pending=np.zeros(n, dtype=bool),
        travel=z.copy(),
        gate=np.zeros(n, dtype=int),
        last_contact=np.full(n, -np.inf),
        g=z.copy(),
        clear=z.copy(),
        acc=np.zeros((n, 3)),
        acc_abs=np.zeros((n, 3)),
        acc_raw=np.zeros((n, 3)),
        acc_obs=z.copy(),
        acc_pred=z.copy(),
        acc_t=z.copy(),
        acc_rot=z.copy(),
        acc_rot0=z.copy(),
        acc_n=np.zeros(n, dtype=int),
        detected=np.zeros(n, dtype=bool),
        isolating=np.full(n, -np.inf),
        kinds=[""] * n,
        rest=[""] * n,
    )


def shape_history(ctx: DetectorContext) -> TrackHistory:
    """The last :data:`SHAPE_HISTORY` s of every vehicle's observed poses (3,)."""
    length = int(round(SHAPE_HISTORY / ctx.dt)) + 1
    return TrackHistory(length, len(ctx.pos), (3,))


def wrap_difference(a: np.ndarray) -> np.ndarray:
    """An angle difference [rad] moved by whole turns into [-pi, pi)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def advance_model(st: DetectorState, ctx: DetectorContext) -> None:
    """One control period of the motor model (see the module docstring)."""
    h, s = ctx.dt, max(1, int(ctx.substeps))
    moved = motor_model(
        st.pose, st.vel, st.rate, st.travel, ctx.commands, ctx.motor_accel,
        ctx.turn_accel, h, s,
    )  # fmt: skip
    if moved is not None:  # the compiled path: the period in one C call
        st.vel, st.rate = moved
        return
    dts = h / s
    v1, v2 = ctx.commands[:, 0], ctx.commands[:, 1]
    heading = st.pose[:, 2] + 0.5 * v2 * h
    target = np.column_stack((v1 * np.cos(heading), v1 * np.sin(heading)))
    lin = ctx.motor_accel * dts  # inf: reached within one substep
    ang = ctx.turn_accel * dts
    start = st.pose[:, :2].copy()
    for _ in range(s):
        st.pose[:, :2] += st.vel * dts
        st.pose[:, 2] += st.rate * dts
        dv = target - st.vel
        norm = np.hypot(dv[:, 0], dv[:, 1])
        scale = np.where(norm > lin, lin / np.maximum(norm, 1e-300), 1.0)
        st.vel = st.vel + dv * scale[:, None]
        st.rate = st.rate + np.clip(v2 - st.rate, -ang, ang)
    st.travel += np.hypot(*(st.pose[:, :2] - start).T)
