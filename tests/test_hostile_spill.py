"""The hostile corpus of spilled records: a temporary directory that fills up.

v0.3: a record spilling to a full TMPDIR ended in a traceback from a finalizer (the
recorder's ``_discard`` closing files whose buffers could not be written), an error
naming no path, and the spill directory left on the full file system. Then the run
ended with one line naming the directory and what the record needs, but with exit 1
and no run directory. Now the run ends there with status ``error``, its samples
written before kept and its run directory written; the line names the directory,
every spill file is closed and the directory removed, and a recorder dropped
half-way raises nothing.
The disk fills up here through the kernel's own ``/dev/full`` (every write fails with
``ENOSPC``) or a file that fails past a size, not a small real file system.
"""

from __future__ import annotations

import errno
import gc
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import HEADON, write_yaml

from sandbox.cli import main
from sandbox.run import recorder as recorder_module
from sandbox.run.recorder import Recorder, SpillError

FULL = "/dev/full"


class FillsUp:
    """A spill file on a file system with ``room`` bytes left.

    Writes past ``room`` fail with ``ENOSPC``; after a failure its buffer holds bytes
    that cannot be written, so ``close`` fails too (as a buffered file does), though
    the file is closed.
    """

    def __init__(self, path: str | os.PathLike[str], room: int) -> None:
        self.file = open(path, "w+b")  # noqa: SIM115 - closed by the recorder
        self.room = room
        self.stuck = False
        self.opened.append(self)

    opened: list[FillsUp] = []

    def write(self, data: bytes) -> int:
        if len(data) > self.room:
            self.stuck = True
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.room -= len(data)
        return self.file.write(data)

    def seek(self, offset: int) -> int:
        return self.file.seek(offset)

    def flush(self) -> None:
        self.file.flush()

    def fileno(self) -> int:
        return self.file.fileno()

    @property
    def closed(self) -> bool:
        return self.file.closed

    def close(self) -> None:
        self.file.close()
        if self.stuck:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.fixture
def small_disk(monkeypatch: pytest.MonkeyPatch) -> Any:
    """Spill files with 20 kB of room each; buffers of about 4 kB."""
    FillsUp.opened = []
    monkeypatch.setattr(recorder_module, "CHUNK_BYTES", 4096)
    monkeypatch.setattr(
        recorder_module,
        "open",
        lambda path, mode: FillsUp(path, 20_000),
        raising=False,
    )
    return FillsUp.opened


def sample(rec: Recorder, k: int, n: int) -> None:
    z2 = np.zeros((n, 2))
    rec.append(
        k * 0.01,
        np.zeros((n, 3)),
        z2,
        z2,
        z2,
        z2,
        np.zeros(n, np.int8),
        np.zeros(n, bool),
        np.zeros(2),
    )


def test_a_full_disk_mid_run_keeps_what_was_written_and_removes_the_directory(
    tmp_path: Path, small_disk: list[FillsUp]
) -> None:
    n = 8
    rec = Recorder(100_000, n, spill_bytes=0, directory=tmp_path)
    assert rec.on_disk
    spill = next(tmp_path.glob("sandbox-record-*"))
    for k in range(100_000):
        sample(rec, k, n)
        if rec.failure is not None:
            break
    message = rec.failure
    assert message is not None and k < 1_000  # 20 kB of room per file
    assert message.startswith(f"{spill}: the run's record cannot be spilled there")
    assert "No space left on device" in message and "TMPDIR" in message
    assert "\n" not in message
    assert not spill.exists()  # removed, on the full file system too
    assert small_disk and all(f.closed for f in small_disk)
    # the samples written before the disk filled up are kept, whole, in order
    arrays = rec.arrays()
    kept = len(arrays["t"])
    assert 0 < kept <= k and f"the {kept} samples written before" in message
    np.testing.assert_allclose(arrays["t"], np.arange(kept) * 0.01)
    assert all(len(a) == kept for a in arrays.values())
    sample(rec, k + 1, n)  # takes no more
    assert len(rec.arrays()["t"]) == kept


def test_a_recorder_dropped_half_way_raises_nothing(
    tmp_path: Path, small_disk: list[FillsUp], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Its finalizer closes files that cannot be flushed without a traceback."""
    rec = Recorder(100_000, 4, spill_bytes=0, directory=tmp_path)
    spill = next(tmp_path.glob("sandbox-record-*"))
    for f in small_disk:
        f.stuck = True  # bytes in every buffer that the disk will not take
    seen: list[object] = []
    monkeypatch.setattr("sys.unraisablehook", seen.append)
    del rec
    gc.collect()
    assert seen == []
    assert not spill.exists() and all(f.closed for f in small_disk)


def test_a_full_disk_at_the_start_names_the_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def full(*args: Any, **kwargs: Any) -> str:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(tempfile, "mkdtemp", full)
    with pytest.raises(SpillError, match=f"^{tmp_path}: the run's record cannot"):
        Recorder(100_000, 4, spill_bytes=0, directory=tmp_path)
    full_files: list[Any] = []
    monkeypatch.undo()
    monkeypatch.setattr(
        recorder_module,
        "open",
        lambda path, mode: full_files.append(open(FULL, mode)) or full_files[-1],  # noqa: SIM115
        raising=False,
    )
    with pytest.raises(SpillError, match="No space left on device"):
        Recorder(100_000, 4, spill_bytes=0, directory=tmp_path)  # the kernel's ENOSPC
    assert list(tmp_path.iterdir()) == []
    assert full_files and all(f.closed for f in full_files)


def test_sandbox_run_on_a_full_tmpdir_keeps_its_outputs_up_to_then(
    tmp_path: Path,
    small_disk: list[FillsUp],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    monkeypatch.setattr(recorder_module, "SPILL_BYTES", 0)  # every record spills
    seen: list[object] = []
    monkeypatch.setattr("sys.unraisablehook", seen.append)
    scenario = write_yaml(tmp_path, {**HEADON, "duration": 20})
    out = tmp_path / "out"
    assert main(["run", str(scenario), "--out", str(out)]) == 1
    gc.collect()
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln]
    assert len(lines) == 1 and "Traceback" not in err
    assert lines[0].startswith("error: at t = ")
    assert f"the run's record stage failed: {tmp}/sandbox-record-" in lines[0]
    assert "No space left on device" in lines[0] and f"are in {out}" in lines[0]
    assert seen == []
    assert list(tmp.iterdir()) == []  # no spill directory left
    assert all(f.closed for f in small_disk)
    # the run directory holds the run up to the failure, status error
    from sandbox import load_run

    run = load_run(out)
    assert run.status == "error" and run.info["error"]["stage"] == "record"
    assert 0 < run.t[-1] < 20.0
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert metrics["status"] == "error"
    assert metrics["error"]["message"].startswith(f"{tmp}/sandbox-record-")
