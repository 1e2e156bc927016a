"""The record as the loop writes it: one sample a period, in memory or spilled to disk.

A :class:`Recorder` is preallocated for the whole run; past :data:`SPILL_BYTES` it
streams its samples to ``.npy`` files in a private directory instead (memory-mapped
when read back), removed when the run's arrays are no longer used, or by the next run
after a crash (:func:`remove_dead_records`). Its :meth:`Recorder.arrays` become a
:class:`~sandbox.run.record.Run`.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import weakref
from pathlib import Path
from typing import Any

import numpy as np

from sandbox.run.output_guard import process_alive

#: Above this size [bytes] a run's record is streamed to files on disk (see
#: :class:`Recorder`); smaller records stay in memory.
SPILL_BYTES = 64 * 2**20
#: Memory of the buffer that collects samples before they are written to disk [bytes].
CHUNK_BYTES = 8 * 2**20

#: The recorded arrays: name -> (shape of one sample given n, dtype).
_FIELDS: dict[str, tuple[Any, Any]] = {
    "t": (lambda n: (), np.float64),
    "pose": (lambda n: (n, 3), np.float64),
    "cmd": (lambda n: (n, 2), np.float64),
    "chi": (lambda n: (n, 2), np.float64),
    "slot": (lambda n: (n, 2), np.float64),
    "target": (lambda n: (n, 2), np.float64),
    "mode": (lambda n: (n,), np.int8),
    "failed": (lambda n: (n,), np.bool_),
    "reference": (lambda n: (2,), np.float64),
}


class Recorder:
    """Storage that the simulation loop fills one sample at a time.

    A small record is preallocated in memory. A record larger than ``spill_bytes``
    (thousands of vehicles, long runs) is streamed to disk instead: samples are
    collected in a buffer of about :data:`CHUNK_BYTES`, each full buffer is appended to
    one ``.npy`` file per array in a temporary directory, and :meth:`arrays` returns
    read-only memory maps of those files. Memory then stays bounded whatever
    ``n x samples``; the files are unlinked as soon as they are mapped (POSIX), so the
    disk space is released with the last array that uses it.

    Parameters
    ----------
    n_samples : int
        Upper bound on the number of samples (the run may stop early).
    n_vehicles : int
    spill_bytes : int, optional
        Record size above which samples go to disk; default :data:`SPILL_BYTES`.
    directory : str or Path, optional
        Where the temporary directory is made; default the system's temporary directory.
    """

    def __init__(
        self,
        n_samples: int,
        n_vehicles: int,
        spill_bytes: int | None = None,
        directory: str | Path | None = None,
    ) -> None:
        T, n = n_samples, n_vehicles
        self.capacity = T
        self.count = 0
        shapes = {k: (f(n), np.dtype(dtype)) for k, (f, dtype) in _FIELDS.items()}
        sample_bytes = sum(
            int(np.prod(shape)) * dtype.itemsize for shape, dtype in shapes.values()
        )
        limit = SPILL_BYTES if spill_bytes is None else spill_bytes
        self.on_disk = T * sample_bytes > limit
        self._shapes = shapes
        self._dir: Path | None = None
        where = (
            Path(directory) if directory is not None else Path(tempfile.gettempdir())
        )
        # Every run (spilling or not) clears what killed runs left, once a process.
        if where not in _CLEARED:
            _CLEARED.add(where)
            remove_dead_records(where)
        if not self.on_disk:
            self._chunk = T
            self._buffers = {
                k: np.zeros((T, *shape), dtype) for k, (shape, dtype) in shapes.items()
            }
            return
        self._chunk = int(max(1, min(T, CHUNK_BYTES // max(sample_bytes, 1))))
        self._buffers = {
            k: np.zeros((self._chunk, *shape), dtype)
            for k, (shape, dtype) in shapes.items()
        }
        self._dir = Path(
            tempfile.mkdtemp(prefix=f"sandbox-record-{os.getpid()}-", dir=where)
        )
        self._files: dict[str, Any] = {}
        # Closes and removes the files if the recorder is dropped before arrays() (a
        # run that failed).
        self._cleanup = weakref.finalize(self, _discard, self._files, self._dir)
        self._offsets: dict[str, int] = {}
        for k, (shape, dtype) in shapes.items():
            # Only the header is written now: the file grows as samples are appended
            # (never a sparse file of the record's full size), and arrays() rewrites
            # the header with the samples actually recorded.
            header = _npy_header(dtype, (T, *shape))
            fh = open(self._dir / f"{k}.npy", "w+b")  # closed by arrays()/_discard()
            fh.write(header)
            self._files[k] = fh
            self._offsets[k] = len(header)
        self._flushed = 0

    def append(
        self,
        t: float,
        pose: np.ndarray,
        cmd: np.ndarray,
        chi: np.ndarray,
        slot: np.ndarray,
        target: np.ndarray,
        mode: np.ndarray,
        failed: np.ndarray,
        reference: np.ndarray,
    ) -> None:
        """Copy one sample in (arrays are copied, so callers may reuse theirs)."""
        k = self.count
        if k >= self.capacity:
            return
        row = k - self._flushed if self.on_disk else k
        b = self._buffers
        b["t"][row] = t
        b["pose"][row] = pose
        b["cmd"][row] = cmd
        b["chi"][row] = chi
        b["slot"][row] = slot
        b["target"][row] = target
        b["mode"][row] = mode
        b["failed"][row] = failed
        b["reference"][row] = reference
        self.count = k + 1
        if self.on_disk and row + 1 == self._chunk:
            self._flush()

    def _flush(self) -> None:
        """Write the buffered samples to the files (disk-backed records only)."""
        rows = self.count - self._flushed
        if rows <= 0:
            return
        for k, fh in self._files.items():
            data = self._buffers[k][:rows]
            fh.seek(self._offsets[k] + self._flushed * data[0].nbytes)
            fh.write(data.tobytes())
        self._flushed = self.count

    def arrays(self) -> dict[str, np.ndarray]:
        """The filled part of every array (read-only memory maps if on disk).

        For a disk-backed record this closes the recorder: call it once, at the end.
        """
        k = self.count
        if not self.on_disk:
            return {name: buf[:k] for name, buf in self._buffers.items()}
        self._flush()
        for name, fh in self._files.items():
            shape, dtype = self._shapes[name]
            fh.seek(0)
            fh.write(_npy_header(dtype, (k, *shape), self._offsets[name]))
            fh.close()
        self._files.clear()
        out = {
            name: np.load(self._dir / f"{name}.npy", mmap_mode="r")[:k]
            for name in self._shapes
        }
        self._buffers = {}
        self._cleanup.detach()
        if os.name == "posix":  # the mappings keep the data; the names can go now
            shutil.rmtree(self._dir, ignore_errors=True)
        else:  # pragma: no cover - files in use cannot be removed elsewhere
            atexit.register(shutil.rmtree, self._dir, ignore_errors=True)
        return out


def _npy_header(dtype: np.dtype, shape: tuple[int, ...], length: int = 0) -> bytes:
    """A ``.npy`` (version 1.0) header for an array of ``shape``.

    Padded to a multiple of 64 bytes, or to ``length`` bytes when given (to rewrite a
    header in place with a smaller shape).
    """
    text = (
        f"{{'descr': {np.lib.format.dtype_to_descr(np.dtype(dtype))!r}, "
        f"'fortran_order': False, 'shape': {tuple(shape)!r}, }}"
    )
    total = length or -(-(10 + len(text) + 1) // 64) * 64
    text = text + " " * (total - 10 - len(text) - 1) + "\n"
    return (
        b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text.encode("latin1")
    )


#: The files a disk-backed record holds.
_RECORD_FILES = frozenset(f"{k}.npy" for k in _FIELDS)


#: Directories whose dead records this process has removed already.
_CLEARED: set[Path] = set()


def remove_dead_records(directory: Path) -> None:
    """Remove record directories that killed runs left in ``directory``.

    Only directories named ``sandbox-record-<pid>-*`` whose process is dead and that
    hold nothing but a record's files are removed (a SIGKILL leaves them behind).
    """
    for path in Path(directory).glob("sandbox-record-*-*"):
        pid = path.name[len("sandbox-record-") :].split("-", 1)[0]
        if not pid.isdigit() or process_alive(int(pid)):
            continue
        try:
            if path.is_symlink() or not path.is_dir():
                continue
            entries = list(path.iterdir())
            if not {e.name for e in entries} <= _RECORD_FILES:
                continue
            for e in entries:
                if e.is_file() and not e.is_symlink():
                    e.unlink()
            path.rmdir()
        except OSError:
            continue


def _discard(files: dict[str, Any], directory: Path) -> None:
    """Close a disk-backed record's files and remove them."""
    for fh in files.values():
        fh.close()
    shutil.rmtree(directory, ignore_errors=True)
