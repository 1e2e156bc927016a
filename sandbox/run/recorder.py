"""The record as the loop writes it: one sample a period, in memory or spilled to disk.

A :class:`Recorder` is preallocated for the whole run; past :data:`SPILL_BYTES` it
streams its samples to ``.npy`` files in a private directory instead (memory-mapped
when read back), removed when the run's arrays are no longer used, or by the next run
after a crash (:func:`remove_dead_records`). Its :meth:`Recorder.arrays` become a
:class:`~sandbox.run.record.Run`.

A spill that cannot start (the temporary directory's file system is full, or
read-only) raises :class:`SpillError`, one line naming the directory and what the
record needs there. One that fails during the run (the disk fills up) keeps the
samples written before (memory maps of its files) and says so in
:attr:`Recorder.failure`, the same one line: the loop then ends the run there with
status ``error``, its outputs written. Either way every spill file is closed and the
directory removed, and a recorder dropped half-way (its run failed) closes and
removes its files without an error of its own.
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

from sandbox.errors import OutputError
from sandbox.run.output_guard import remove_dead_dirs

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


class SpillError(OutputError):
    """A run's record could not be spilled to disk (names the directory)."""


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
        #: The one line of a spill that failed during the run (None: none): the
        #: samples written before it are kept, the recorder takes no more.
        self.failure: str | None = None
        self._kept: dict[str, np.ndarray] | None = None
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
        self._bytes = T * sample_bytes
        try:
            self._dir = Path(
                tempfile.mkdtemp(prefix=f"sandbox-record-{os.getpid()}-", dir=where)
            )
        except OSError as exc:
            raise SpillError(self._why(where, exc)) from None
        self._files: dict[str, Any] = {}
        # Closes and removes the files if the recorder is dropped before arrays() (a
        # run that failed).
        self._cleanup = weakref.finalize(self, _discard, self._files, self._dir)
        self._offsets: dict[str, int] = {}
        try:
            for k, (shape, dtype) in shapes.items():
                # Only the header is written now: the file grows as samples are
                # appended (never a sparse file of the record's full size), and
                # arrays() rewrites the header with the samples actually recorded.
                header = _npy_header(dtype, (T, *shape))
                fh = open(self._dir / f"{k}.npy", "w+b")  # closed by arrays()/_discard
                self._files[k] = fh
                fh.write(header)
                fh.flush()
                self._offsets[k] = len(header)
        except OSError as exc:
            self._fail(exc)
        self._flushed = 0

    def _why(self, where: Path, exc: OSError) -> str:
        """The one line of a spill that failed in ``where``."""
        need = self._bytes / 1e6
        return (
            f"{where}: the run's record cannot be spilled there "
            f"({exc.strerror or type(exc).__name__}; it needs about {need:,.0f} MB); "
            "free space there, or set TMPDIR to a directory on a larger file system"
        )

    def _fail(self, exc: OSError) -> None:
        """Close and remove the spill files, then raise :class:`SpillError`."""
        directory = self._dir
        self._cleanup.detach()
        _discard(self._files, directory)
        self._buffers = {}
        raise SpillError(self._why(directory, exc)) from None

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
        try:
            for k, fh in self._files.items():
                data = self._buffers[k][:rows]
                fh.seek(self._offsets[k] + self._flushed * data[0].nbytes)
                fh.write(data.tobytes())
                fh.flush()  # a full disk says so now, not at close
        except OSError as exc:
            self._keep(exc)
            return
        self._flushed = self.count

    def _keep(self, exc: OSError) -> None:
        """The spill failed: keep the samples written, remove the files; say why.

        The samples flushed before (all arrays written up to the same sample) are
        mapped read-only and the files closed and removed (the mappings keep their
        data); those still in the buffer are lost. :attr:`failure` says it in one
        line, and the recorder takes no more samples.
        """
        directory = self._dir
        self._cleanup.detach()
        k = self._flushed
        kept = {}
        for name, (shape, dtype) in self._shapes.items():
            if k == 0:
                kept[name] = np.zeros((0, *shape), dtype)
                continue
            kept[name] = np.memmap(
                directory / f"{name}.npy",
                dtype=dtype,
                mode="r",
                offset=self._offsets[name],
                shape=(k, *shape),
            )
        _discard(self._files, directory)
        self._buffers = {}
        self._kept = kept
        self.count = self.capacity = k
        self.failure = (
            f"{self._why(directory, exc)} (the {k} samples written before are kept)"
        )

    def arrays(self) -> dict[str, np.ndarray]:
        """The filled part of every array (read-only memory maps if on disk).

        For a disk-backed record this closes the recorder: call it once, at the end.
        Where the spill failed (:attr:`failure`), the samples written before.
        """
        k = self.count
        if not self.on_disk:
            return {name: buf[:k] for name, buf in self._buffers.items()}
        if self._kept is None:
            self._flush()
        if self._kept is not None:  # the spill failed: what it kept
            return self._kept
        try:
            for name, fh in self._files.items():
                shape, dtype = self._shapes[name]
                fh.seek(0)
                fh.write(_npy_header(dtype, (k, *shape), self._offsets[name]))
                fh.close()
            out = {
                name: np.load(self._dir / f"{name}.npy", mmap_mode="r")[:k]
                for name in self._shapes
            }
        except OSError as exc:
            self._keep(exc)
            return self._kept
        self._files.clear()
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
    remove_dead_dirs(directory, "sandbox-record-", _RECORD_FILES)


def _discard(files: dict[str, Any], directory: Path) -> None:
    """Close a disk-backed record's files and remove them, whatever fails.

    A file whose buffered bytes cannot be written (a full disk) is closed all the
    same; nothing here raises, so a finalizer never prints a traceback.
    """
    for fh in files.values():
        try:
            fh.close()  # closes the file even when its buffer cannot be written
        except OSError:
            pass
    files.clear()
    shutil.rmtree(directory, ignore_errors=True)
