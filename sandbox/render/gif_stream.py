"""An animated GIF written a chunk of frames at a time, with one global palette.

:mod:`sandbox.render.animation` draws frames as palette indices; :class:`GifStream`
encodes them with imageio (its Pillow plugin), a chunk at a time so that memory stays
bounded on long runs, and joins the chunks into one GIF89a stream whose global colour
table is the run's palette (index 0, white, is the background).
"""

from __future__ import annotations

import math
import struct
from typing import IO

import imageio.v3 as iio
import numpy as np

__all__ = ["GifStream"]


class GifStream:
    """One GIF89a stream assembled from GIFs that imageio encodes a chunk at a time.

    The header (logical screen, global colour table = the run's palette, NETSCAPE loop
    block) is written once; from each chunk only the frames are kept (graphic control
    extensions, image descriptors and LZW data), with any local colour table dropped.
    imageio receives the frames as ``L`` images of palette indices with
    ``optimize=False``, so Pillow writes the indices unchanged (it neither quantizes nor
    remaps them) and only its placeholder colour tables need replacing.

    Every frame after the first codes the pixels that did not change as the transparent
    index ``len(palette)`` (no disposal: the previous frame shows through), which about
    halves the file size; Pillow crops each frame to the box that changed.
    """

    def __init__(
        self, fh: IO[bytes], width: int, height: int, palette: np.ndarray, loop: int = 0
    ) -> None:
        if len(palette) > 255:
            raise ValueError("the palette must leave one index free for transparency")
        self.fh = fh
        self.frames = 0
        self.duration_ms = 0
        self.clear = len(palette)  # transparent index: "unchanged since last frame"
        self.previous: np.ndarray | None = None
        bits = max(1, int(math.ceil(math.log2(len(palette) + 1))))
        table = np.full((1 << bits, 3), 255, dtype=np.uint8)
        table[: len(palette)] = palette
        fh.write(b"GIF89a")
        fh.write(struct.pack("<HHBBB", width, height, 0x80 | 0x70 | (bits - 1), 0, 0))
        fh.write(table.tobytes())
        fh.write(b"!\xff\x0bNETSCAPE2.0\x03\x01" + struct.pack("<H", loop) + b"\x00")

    def add(self, frames: list[np.ndarray], delays_ms: list[int]) -> None:
        """Encode frames (palette indices, (H, W) uint8) with their delays [ms]."""
        if not frames:
            return
        batch = np.empty((len(frames), *frames[0].shape), dtype=np.uint8)
        for j, frame in enumerate(frames):
            if self.previous is None:
                batch[j] = frame
            else:
                _changes(frame, self.previous, self.clear, out=batch[j])
            self.previous = frame
        duration: int | list[int] = delays_ms if len(frames) > 1 else delays_ms[0]
        data = iio.imwrite(
            "<bytes>",
            batch,
            extension=".gif",
            plugin="pillow",
            is_batch=True,
            duration=duration,
            loop=0,
            optimize=False,
            transparency=self.clear,
        )
        self.fh.write(_frame_blocks(data))
        self.frames += len(frames)
        self.duration_ms += int(sum(delays_ms))

    def close(self) -> None:
        """Write the trailer."""
        self.fh.write(b";")


def _changes(
    frame: np.ndarray, previous: np.ndarray, clear: int, out: np.ndarray
) -> None:
    """Copy into ``out`` the changed pixels of ``frame``, and ``clear`` elsewhere.

    All arrays are (H, W) uint8. The changed box is found comparing up to 8 pixels at a
    time, then refined pixel by pixel.
    """
    width = frame.shape[1]
    word = next(b for b in (8, 4, 2, 1) if width % b == 0)
    as_words = np.dtype(f"u{word}")
    moved = frame.view(as_words) != previous.view(as_words)
    out.fill(clear)
    rows = np.flatnonzero(moved.any(axis=1))
    if rows.size == 0:
        return
    r0, r1 = int(rows[0]), int(rows[-1]) + 1
    cols = np.flatnonzero(moved[r0:r1].any(axis=0))
    c0, c1 = int(cols[0]) * word, (int(cols[-1]) + 1) * word
    box = frame[r0:r1, c0:c1]
    np.copyto(out[r0:r1, c0:c1], box, where=box != previous[r0:r1, c0:c1])


def _skip_subblocks(data: bytes, pos: int) -> int:
    """Position just after the data sub-blocks starting at ``pos``."""
    while True:
        length = data[pos]
        pos += 1 + length
        if length == 0:
            return pos


def _frame_blocks(data: bytes) -> bytes:
    """Extract the frames of a GIF stream, without header, trailer nor colour tables."""
    if data[:6] not in (b"GIF87a", b"GIF89a"):
        raise ValueError("not a GIF stream")
    flags = data[10]
    pos = 13 + (3 << ((flags & 7) + 1) if flags & 0x80 else 0)
    out = bytearray()
    started = False
    while True:
        block = data[pos]
        if block == 0x3B:  # trailer
            return bytes(out)
        if block == 0x21:  # extension: keep graphic control and later ones
            end = _skip_subblocks(data, pos + 2)
            started = started or data[pos + 1] == 0xF9
            if started:
                out += data[pos:end]
            pos = end
        elif block == 0x2C:  # image descriptor
            started = True
            desc = bytearray(data[pos : pos + 10])
            pos += 10
            if desc[9] & 0x80:
                pos += 3 << ((desc[9] & 7) + 1)
                desc[9] &= 0x40  # keep only the interlace flag
            end = _skip_subblocks(data, pos + 1)  # after the LZW minimum code size
            out += desc + data[pos:end]
            pos = end
        else:
            raise ValueError(f"unexpected GIF block 0x{block:02x} at byte {pos}")
