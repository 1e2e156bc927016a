"""The command line under hostile options, faults and signals.

Option values are checked when the command line is read, by the option's name; GIF
options are bounded before a run starts; messages name the user's paths; a signal at
any phase ends the command with status 130 and no traceback, leaving no temporary file;
a killed run's disk-backed record is cleaned by a later run.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import sandbox.loop.simulation as simulation_module
import sandbox.render.animation as render
import sandbox.run.output as output_module
from sandbox.cli import main
from sandbox.run.recorder import Recorder, remove_dead_records

TINY = {
    "name": "tiny",
    "duration": 0.3,
    "reference": {"type": "circle", "center": [0, 0], "radius": 5, "speed": 1},
    "formation": {"law": "rotating"},
    "vehicles": [
        {"name": "leader", "pose": [5, 0, 1.5708], "leader": True},
        {"name": "red", "pose": [4, -1, 1.5708], "offset": [-1, 1]},
    ],
}


@pytest.fixture
def src(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(json.dumps(TINY), encoding="utf-8")
    return path


def usage_error(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err.strip().splitlines()[-1]


# ------------------------------------------------------------------- GIF options
@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("--fps", "0.001"),
        ("--fps", "0"),
        ("--fps", "nan"),
        ("--fps", "inf"),
        ("--fps", "1e309"),
        ("--fps", "51"),
        ("--size", "20000"),
        ("--size", "70000"),
        ("--size", "0"),
        ("--size", "10.5"),
        ("--size", "1" + "0" * 5000),
        ("--speed", "1e-6"),
        ("--speed", "-1"),
        ("--speed", "1e400"),
    ],
)
@pytest.mark.parametrize("command", ["run", "render"])
def test_gif_options_out_of_bounds_are_refused_by_name(
    command: str,
    option: str,
    value: str,
    src: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    target = str(src) if command == "run" else str(tmp_path / "no-run")
    argv = [command, target, "--gif", str(tmp_path / "x.gif"), option, value]
    line = usage_error(argv, capsys)
    assert line.startswith(f"sandbox {command}: error: argument {option}: expected")
    assert not (tmp_path / "runs").exists() and not (tmp_path / "x.gif").exists()


def test_too_many_frames_are_refused_before_the_run_starts(
    src: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    def never(*args, **kwargs):
        raise AssertionError("simulated although the GIF options were refused")

    monkeypatch.setattr(simulation_module.Simulation, "run", never)
    out = tmp_path / "out"
    argv = ["run", str(src), "--out", str(out), "--gif", str(tmp_path / "x.gif")]
    assert main([*argv, "--duration", "4000", "--fps", "50", "--speed", "1"]) == 2
    err = capsys.readouterr().err
    assert "would make 200,000 frames" in err and "--fps" in err and "--speed" in err
    assert not out.exists()


# --------------------------------------------------------------- option messages
@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--duration", ""], "argument --duration: expected a number, got ''"),
        (["--duration", "abc"], "argument --duration: expected a number, got 'abc'"),
        (["--duration", "-1"], "argument --duration: expected a number > 0"),
        (["--out", ""], "argument --out: expected a path, got ''"),
        (["--gif", " "], "argument --gif: expected a path"),
    ],
)
def test_run_options_are_checked_by_the_name_typed(
    extra: list[str], expected: str, src: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert expected in usage_error(["run", str(src), *extra], capsys)


def test_the_last_set_of_a_field_is_blamed(
    src: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert (
        main(["validate", str(src), "--set", "duration=1", "--set", "duration=-1"]) == 2
    )
    err = capsys.readouterr().err
    assert "[from --set duration=-1]" in err and "duration=1]" not in err


def test_a_bad_duration_option_is_blamed_as_duration(
    src: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert (
        main(["run", str(src), "--out", str(tmp_path / "o"), "--duration", "1e20"]) == 2
    )
    err = capsys.readouterr().err
    assert "[from --duration 1e+20]" in err and "--set" not in err


@pytest.mark.parametrize("value", ["0", "-3", "two", ""])
def test_bad_jobs_are_errors(
    value: str, src: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    line = usage_error(["compare", str(src), "--jobs", value], capsys)
    assert "argument --jobs: expected a whole number >= 1" in line


def test_too_many_jobs_are_capped_at_the_cores(
    src: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["compare", str(src), "--strategies", "none", "--jobs", "1000"]) == 0
    assert "warning: --jobs 1000 capped at the" in capsys.readouterr().err


# ----------------------------------------------------------- paths in messages
def test_a_gif_on_a_full_or_read_only_disk_names_the_users_path(
    src: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    out = tmp_path / "out"
    assert main(["run", str(src), "--out", str(out)]) == 0
    gif = tmp_path / "x.gif"
    real = os.replace

    def read_only(a, b):
        if Path(b) == gif:
            raise OSError(30, "Read-only file system", str(a))
        real(a, b)

    monkeypatch.setattr(render.os, "replace", read_only)
    capsys.readouterr()
    assert main(["render", str(out), "--gif", str(gif)]) == 1
    err = capsys.readouterr().err
    assert err == f"error: {gif}: cannot write the GIF (Read-only file system)\n"
    monkeypatch.setattr(render.os, "replace", real)

    def full(self, *args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(render._GifStream, "add", full)
    assert main(["render", str(out), "--gif", str(gif)]) == 1
    err = capsys.readouterr().err
    assert err == f"error: {gif}: cannot write the GIF (No space left on device)\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "tiny.yaml"]


def test_a_full_disk_while_writing_a_run_names_the_run_directory(
    src: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    import sandbox.run.run_dir as output  # where the writer lives

    def full(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(output, "write_csv", full)
    out = tmp_path / "out"
    assert main(["run", str(src), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err == f"error: {out}: cannot write the run (No space left on device)\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tiny.yaml"]


# ------------------------------------------------------------------------ signals
def command(*argv: str) -> list[str]:
    return [sys.executable, "-m", "sandbox", *argv]


def catches_sigterm(pid: int) -> bool:
    """Whether the process has a SIGTERM handler (sandbox's start-up installs one)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    caught = next(
        int(ln.split()[1], 16) for ln in status.splitlines() if ln.startswith("SigCgt:")
    )
    return bool(caught >> (signal.SIGTERM - 1) & 1)


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc")
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["INT", "TERM"])
@pytest.mark.parametrize("delay", [0.0, 0.1, 0.3])
def test_a_signal_during_start_up_prints_no_traceback(
    sig: signal.Signals, delay: float, src: Path
) -> None:
    """From the package's first line on (Python's own start-up comes before it)."""
    proc = subprocess.Popen(
        command("validate", str(src)),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 30
    while not catches_sigterm(proc.pid):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no handler while starting up"
        time.sleep(0.001)
    time.sleep(delay)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    # 0: it had finished already; -SIGINT or -SIGTERM: it had finished and Python,
    # shutting down, had restored the default handlers (after the command's last line).
    assert proc.returncode in (0, 130, -signal.SIGINT, -sig), err
    if proc.returncode == 130:
        assert err.strip().splitlines()[-1] == "interrupted"


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["INT", "TERM"])
def test_a_signal_while_the_gif_renders_exits_130_and_leaves_no_file(
    sig: signal.Signals, tmp_path: Path
) -> None:
    doc = dict(TINY, duration=40.0, record_every=5)
    path = tmp_path / "long.yaml"
    path.write_text(json.dumps(doc), encoding="utf-8")
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 0
    gifs = tmp_path / "gifs"
    gifs.mkdir()
    proc = subprocess.Popen(
        command(
            "render",
            str(out),
            "--gif",
            str(gifs / "x.gif"),
            "--fps",
            "50",
            "--size",
            "1024",
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 60
    while not list(gifs.glob(".x.gif.*.tmp")):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the GIF never started"
        time.sleep(0.01)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.strip().splitlines()[-1] == "interrupted"
    assert list(gifs.iterdir()) == []


INTERRUPTED_COMMANDS = {
    # An interrupt that leaves a module half imported: its next import fails.
    "half_import": (
        "import signal\n"
        "    try:\n"
        "        signal.raise_signal(signal.SIGTERM)\n"
        "    except KeyboardInterrupt:\n"
        "        pass  # a library that swallows it\n"
        "    raise ImportError('partially initialized module')"
    ),
    # A KeyboardInterrupt that ends a string exec (as a dataclass is made while a
    # module is imported): under `python -m`, CPython would exit by SIGINT (-2).
    "string_exec": 'exec("raise KeyboardInterrupt", {})',
    # One that lands in a __del__ method: Python can only print it and go on.
    "lost_in_del": (
        "class Dropped:\n"
        "        def __del__(self):\n"
        "            raise KeyboardInterrupt\n"
        "    Dropped()"
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("where", sorted(INTERRUPTED_COMMANDS))
def test_an_interrupt_python_mishandles_still_exits_130(
    where: str, tmp_path: Path
) -> None:
    module = tmp_path / "interrupted_command.py"
    module.write_text(
        "import sys\n"
        "import sandbox.cli as cli\n"
        "def interrupted(args):\n"
        f"    {INTERRUPTED_COMMANDS[where]}\n"
        "cli.load_cli_plugins = interrupted\n"
        "sys.exit(cli.main(['list']))\n",
        encoding="utf-8",
    )
    env = dict(os.environ, PYTHONPATH=str(tmp_path))
    proc = subprocess.run(
        [sys.executable, "-m", "interrupted_command"],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=60,
    )
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == "interrupted"
    assert "Exception ignored" not in proc.stderr and "Traceback" not in proc.stderr


def test_a_signal_while_outputs_are_written_finishes_them_and_exits_130(
    src: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    real = output_module.write_run_dir

    def signalled(run, metrics, out_dir, **options):
        os.kill(os.getpid(), signal.SIGTERM)  # arrives after the last step
        return real(run, metrics, out_dir, **options)

    # `sandbox run` imports its writer when it runs: patch it where it lives
    monkeypatch.setattr(output_module, "write_run_dir", signalled)
    out = tmp_path / "out"
    gif = tmp_path / "x.gif"
    assert main(["run", str(src), "--out", str(out), "--gif", str(gif)]) == 130
    err = capsys.readouterr().err
    assert "its outputs are complete in" in err
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert metrics["status"] == "ok"
    assert not gif.exists()


# ---------------------------------------------------------- disk-backed records
def test_a_record_grows_with_its_samples_and_maps_back(tmp_path: Path) -> None:
    rec = Recorder(1000, 3, spill_bytes=0, directory=tmp_path)
    files = list(next(tmp_path.glob("sandbox-record-*")).iterdir())
    assert max(f.stat().st_size for f in files) < 1024  # headers only, no sparse file
    pose = np.arange(9.0).reshape(3, 3)
    for k in range(10):
        rec.append(
            k * 0.1,
            pose + k,
            np.zeros((3, 2)),
            np.zeros((3, 2)),
            np.zeros((3, 2)),
            np.zeros((3, 2)),
            np.zeros(3, np.int8),
            np.zeros(3, bool),
            np.zeros(2),
        )
    arrays = rec.arrays()
    assert arrays["pose"].shape == (10, 3, 3)
    assert arrays["pose"][7].tolist() == (pose + 7).tolist()
    assert arrays["t"][-1] == pytest.approx(0.9)
    assert list(tmp_path.iterdir()) == []


def dead_pid() -> int:
    done = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    return int(done.stdout)


def test_records_of_dead_runs_are_removed_and_nothing_else(tmp_path: Path) -> None:
    pid = dead_pid()
    dead = tmp_path / f"sandbox-record-{pid}-abc"
    dead.mkdir()
    (dead / "pose.npy").write_bytes(b"\x93NUMPY")
    foreign = tmp_path / f"sandbox-record-{pid}-def"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("mine", encoding="utf-8")
    unnamed = tmp_path / "sandbox-record-xyz"
    unnamed.mkdir()
    alive = tmp_path / f"sandbox-record-{os.getppid()}-ghi"
    alive.mkdir()
    remove_dead_records(tmp_path)
    assert not dead.exists()
    assert foreign.exists() and unnamed.exists() and alive.exists()


@pytest.mark.skipif(not Path("/proc").exists(), reason="needs /proc")
def test_a_killed_runs_record_is_small_and_removed_by_the_next_record(
    tmp_path: Path,
) -> None:
    doc = dict(TINY, duration=3600.0)
    path = tmp_path / "long.yaml"
    path.write_text(json.dumps(doc), encoding="utf-8")
    records = tmp_path / "tmp"
    records.mkdir()
    proc = subprocess.Popen(
        command("run", str(path), "--out", str(tmp_path / "out")),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env={**os.environ, "CI": "1", "TMPDIR": str(records)},
    )
    deadline = time.monotonic() + 60
    while not list(records.glob("sandbox-record-*")):
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.02)
    time.sleep(0.3)
    proc.kill()
    proc.communicate(timeout=60)
    (left,) = records.glob(f"sandbox-record-{proc.pid}-*")
    apparent = sum(f.stat().st_size for f in left.iterdir())
    full = 360_001 * 2 * (8 * 13 + 2) + 360_001 * 8 * 3
    assert apparent < full / 4, f"{apparent:,} of {full:,} bytes preallocated"
    # v0.2 removed it only when a later run's record spilled to disk too: a run of
    # any size clears it now (once a process)
    Recorder(10, 1, directory=records).arrays()
    assert list(records.iterdir()) == []
