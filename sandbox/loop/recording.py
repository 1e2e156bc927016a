"""The record of K worlds as the loop writes it: stacked in memory, or on disk each.

A sample of every world is written at once into arrays of shape ``(T, K, n, ...)``;
a world that ends early (diverged, a plug-in failed, a reconfiguration of the batch)
has its last sample written alone and its arrays copied out at once, so the samples
of the others may then overwrite its column. A world whose record is larger than
:data:`~sandbox.run.recorder.SPILL_BYTES` keeps a
:class:`~sandbox.run.recorder.Recorder` of its own, streamed to disk, and is appended
to world by world; where its spill fails (a full disk), the samples written before
are kept and :meth:`LoopRecord.failure` says why (the loop ends that world there).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sandbox import accel
from sandbox.run.recorder import Recorder

#: The recorded arrays of one sample: name -> (trailing shape given n, dtype).
_FIELDS = {
    "pose": (3, np.float64),
    "cmd": (2, np.float64),
    "chi": (2, np.float64),
    "slot": (2, np.float64),
    "target": (2, np.float64),
    "mode": (None, np.int8),
    "failed": (None, np.bool_),
}


class LoopRecord:
    """Samples of K worlds of ``n`` vehicles, at most ``capacity`` each.

    Parameters
    ----------
    capacity, K, n : int
    spill_bytes : int, optional
        As for :class:`~sandbox.run.recorder.Recorder` (one world's record).
    """

    def __init__(
        self, capacity: int, K: int, n: int, spill_bytes: int | None = None
    ) -> None:
        self.capacity, self.K, self.n = capacity, K, n
        self.count = 0
        first = Recorder(capacity, n, spill_bytes)
        self.on_disk = first.on_disk
        if self.on_disk:
            self._worlds = [first] + [
                Recorder(capacity, n, spill_bytes) for _ in range(K - 1)
            ]
            return
        del first
        T = capacity
        self._t = np.zeros(T)
        self._buf = {
            name: np.zeros((T, K, n) if width is None else (T, K, n, width), dtype)
            for name, (width, dtype) in _FIELDS.items()
        }
        self._reference = np.zeros((T, K, 2))

    def append(
        self,
        t: float,
        pos: np.ndarray,
        theta: np.ndarray,
        v1: np.ndarray,
        v2: np.ndarray,
        chi: np.ndarray,
        slot: np.ndarray,
        target: np.ndarray,
        mode: np.ndarray,
        failed: np.ndarray,
        point: np.ndarray,
        worlds: Sequence[int],
    ) -> None:
        """One sample of the live ``worlds`` (stacked rows ``(K n, ...)``).

        ``point`` is the reference point of every world, shape (K, 2) or (2,).
        """
        c = self.count
        if c >= self.capacity:
            return
        K = self.K
        if self.on_disk:
            point = np.broadcast_to(point, (K, 2))
            for w in worlds:
                self._append_world(
                    w, t, pos, theta, v1, v2, chi, slot, target, mode, failed, point[w]
                )
            self.count = c + 1
            return
        period = accel.module("period")  # a sample of every world in one C call
        if period is not None:
            b = self._buf
            try:
                period.record_sample(
                    c=c,
                    pos=pos,
                    theta=theta,
                    v1=v1,
                    v2=v2,
                    chi=chi,
                    slot=slot,
                    target=target,
                    mode=mode,
                    failed=failed,
                    pose_out=b["pose"],
                    cmd_out=b["cmd"],
                    chi_out=b["chi"],
                    slot_out=b["slot"],
                    target_out=b["target"],
                    mode_out=b["mode"],
                    failed_out=b["failed"],
                )
            except (BufferError, TypeError, ValueError):  # not such arrays: numpy
                self._write(
                    c, None, t, pos, theta, v1, v2, chi, slot, target, mode, failed
                )
            else:
                self._t[c] = t
        else:
            self._write(c, None, t, pos, theta, v1, v2, chi, slot, target, mode, failed)
        self._reference[c] = point
        self.count = c + 1

    def append_last(
        self,
        w: int,
        t: float,
        pos: np.ndarray,
        theta: np.ndarray,
        v1: np.ndarray,
        v2: np.ndarray,
        chi: np.ndarray,
        slot: np.ndarray,
        target: np.ndarray,
        mode: np.ndarray,
        failed: np.ndarray,
        point: np.ndarray,
    ) -> dict[str, np.ndarray]:
        """World ``w``'s last sample (its rows only), then its arrays (it ends now)."""
        if self.on_disk:
            rec = self._worlds[w]
            if rec.count < self.capacity:
                self._append_world(
                    w, t, pos, theta, v1, v2, chi, slot, target, mode, failed, point
                )
            return rec.arrays()
        c = self.count
        if c >= self.capacity:
            return self.arrays(w)
        self._write(c, w, t, pos, theta, v1, v2, chi, slot, target, mode, failed)
        self._reference[c, w] = point
        return self.arrays(w, c + 1)

    def _write(self, c, w, t, pos, theta, v1, v2, chi, slot, target, mode, failed):
        """Sample ``c`` of every world (``w`` None), or of world ``w`` alone."""
        K, n, b = self.K, self.n, self._buf
        self._t[c] = t
        if w is None:
            at: tuple = (c,)

            def part(a: np.ndarray, *shape: int) -> np.ndarray:
                return a.reshape(K, n, *shape)

        else:
            at, rows = (c, w), slice(w * n, (w + 1) * n)

            def part(a: np.ndarray, *shape: int) -> np.ndarray:
                return a[rows]

        pose, cmd = b["pose"][at], b["cmd"][at]
        pose[..., :2] = part(pos, 2)
        pose[..., 2] = part(theta)
        cmd[..., 0] = part(v1)
        cmd[..., 1] = part(v2)
        b["chi"][at] = part(chi, 2)
        b["slot"][at] = part(slot, 2)
        b["target"][at] = part(target, 2)
        b["mode"][at] = part(mode)
        b["failed"][at] = part(failed)

    def _append_world(
        self, w, t, pos, theta, v1, v2, chi, slot, target, mode, failed, point
    ) -> None:
        n = self.n
        rows = slice(w * n, (w + 1) * n)
        self._worlds[w].append(
            t,
            np.concatenate((pos[rows], theta[rows, None]), axis=1),
            np.stack((v1[rows], v2[rows]), axis=1),
            chi[rows],
            slot[rows],
            target[rows],
            mode[rows],
            failed[rows],
            point,
        )

    def failure(self, w: int) -> str | None:
        """Why world ``w``'s record stopped taking samples (None: it did not).

        A record spilled to disk whose spill failed
        (:attr:`~sandbox.run.recorder.Recorder.failure`); a record in memory never
        fails.
        """
        return self._worlds[w].failure if self.on_disk else None

    def arrays(self, w: int, count: int | None = None) -> dict[str, np.ndarray]:
        """World ``w``'s first ``count`` samples (default all so far), its own copy.

        A disk-backed world's arrays are its recorder's read-only memory maps.
        """
        if self.on_disk:
            return self._worlds[w].arrays()
        c = self.count if count is None else count
        out = {"t": self._t[:c].copy()}
        for name, buf in self._buf.items():
            out[name] = np.ascontiguousarray(buf[:c, w])
        out["reference"] = np.ascontiguousarray(self._reference[:c, w])
        order = ("t", "pose", "cmd", "chi", "slot", "target", "mode", "failed")
        return {name: out[name] for name in (*order, "reference")}
