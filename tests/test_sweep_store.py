"""The results store of a sweep under damage, forgery, a second writer, write errors.

A damaged file is named in one line and never raises a traceback; the table is
rebuilt from the run files; a run file counts only for the run it is; a store takes
one sweep at a time; a file that cannot be written is named by the user's path.
"""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest
from helpers import write_yaml
from test_sweep import base_doc, read_csv

from sandbox.cli import main
from sandbox.study import store as store_module
from sandbox.study.spec import build_spec
from sandbox.study.store import Store


@pytest.fixture
def base(tmp_path: Path) -> Path:
    return write_yaml(tmp_path, base_doc(duration=0.5), "base.yaml")


def sweep(base: Path, out: Path, *extra: str) -> list[str]:
    cmd = ["sweep", str(base), "--grid", "recovery.beta=1,2", "--seeds", "0:2"]
    return [*cmd, "--out", str(out), *extra]


@pytest.fixture
def done(tmp_path: Path, base: Path, capsys) -> Path:
    out = tmp_path / "out"
    assert main(sweep(base, out)) == 0
    capsys.readouterr()
    return out


def errors(capsys: pytest.CaptureFixture[str]) -> list[str]:
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return [ln for ln in err.splitlines() if ln]


# ------------------------------------------------------------------ N4: damage
@pytest.mark.parametrize(
    "damage",
    [
        pytest.param(lambda t: t[: len(t) // 2 + 7], id="cut_mid_line"),
        pytest.param(lambda t: "a,b,c\n" + t.split("\n", 1)[1], id="wrong_header"),
        pytest.param(lambda t: "\x00\xff\xfe binary \x00" * 50, id="binary"),
        pytest.param(lambda t: "", id="empty"),
    ],
)
@pytest.mark.parametrize("command", ["table", "plot"])
def test_a_damaged_results_csv_is_named_and_rebuilt(done, capsys, damage, command):
    csv_path = done / "results.csv"
    good = csv_path.read_bytes()
    text = good.decode("utf-8")
    bad = damage(text)
    csv_path.write_bytes(bad.encode("utf-8", "surrogateescape"))
    args = ["sweep", command, str(done)]
    if command == "plot":
        args += ["--out", str(done / "figs")]
    assert main(args) == 0
    lines = errors(capsys)
    assert lines == [
        f"warning: {csv_path}: does not match the run files; rebuilt from the run files"
    ]
    assert csv_path.read_bytes() == good  # the same bytes as the sweep wrote


def test_a_missing_results_csv_is_rebuilt(done, capsys):
    good = (done / "results.csv").read_bytes()
    (done / "results.csv").unlink()
    assert main(["sweep", "table", str(done)]) == 0
    assert "missing; rebuilt from the run files" in errors(capsys)[0]
    assert (done / "results.csv").read_bytes() == good


@pytest.mark.parametrize(
    ("content", "text"),
    [
        ("[1, 2]", "not a sweep description (list)"),
        ("{not json", "not JSON"),
        ('{"grid": [1]}', "grid: not a mapping"),
        ('{"seeds": "0:2"}', "seeds: not [first, end]"),
    ],
)
@pytest.mark.parametrize("command", ["run", "table", "plot"])
def test_a_damaged_sweep_json_is_one_line(done, base, capsys, content, text, command):
    (done / "sweep.json").write_text(content, encoding="utf-8")
    if command == "run":
        status, args = 2, sweep(base, done)
    else:
        status, args = (2 if command == "plot" else 1), ["sweep", command, str(done)]
    assert main(args) == status
    lines = errors(capsys)
    assert len(lines) == 1 and f"{done / 'sweep.json'}: {text}" in lines[0], lines


@pytest.mark.parametrize(
    ("content", "text"),
    [
        ('{"row": 5}', "run_id:"),
        ("[1]", "not a run file (list)"),
        ("{cut", "not JSON"),
        ("", "not JSON"),
    ],
)
def test_a_damaged_run_file_is_named_and_computed_again(
    done, base, capsys, content, text
):
    run = sorted((done / "runs").glob("*.json"))[0]
    good = json.loads(run.read_text())
    run.write_text(content, encoding="utf-8")
    assert main(sweep(base, done)) == 0
    lines = errors(capsys)
    assert lines == [f"warning: {run}: {text}" + lines[0].split(text, 1)[1]]
    assert lines[0].endswith("; computed again")
    assert json.loads(run.read_text())["row"] == good["row"]
    assert len(read_csv(done / "results.csv")) == 4


def test_a_damaged_run_file_under_table_is_left_out(done, capsys):
    run = sorted((done / "runs").glob("*.json"))[0]
    run.write_text('{"row": 5}', encoding="utf-8")
    assert main(["sweep", "table", str(done), "--format", "csv"]) == 0
    lines = errors(capsys)
    assert lines[0].startswith(f"warning: {run}: ") and "left out" in lines[0]
    assert len(read_csv(done / "results.csv")) == 3


# ------------------------------------------------------------------ N6: forgery
def test_a_run_file_of_another_sweep_is_not_taken(tmp_path, base, done, capsys):
    # The same values and seed from another base (another duration): the same name.
    other = tmp_path / "other"
    assert main([*sweep(base, other), "--set", "duration=0.2"]) == 0
    capsys.readouterr()
    name = sorted(p.name for p in (done / "runs").glob("*.json"))[0]
    (done / "runs" / name).write_bytes((other / "runs" / name).read_bytes())
    assert main(sweep(base, done)) == 0
    lines = errors(capsys)
    assert lines == [
        f"warning: {done / 'runs' / name}: base_digest: not this sweep's base scenario "
        "and --set; computed again"
    ]
    doc = json.loads((done / "runs" / name).read_text())
    assert doc["metrics"]["duration"] == 0.5


def test_a_run_file_under_another_runs_name_is_not_taken(done, base, capsys):
    a, b = sorted((done / "runs").glob("*.json"))[:2]
    doc = json.loads(a.read_text())
    doc["run_id"] = b.stem  # a copy renamed, with its id edited to match
    b.write_text(json.dumps(doc), encoding="utf-8")
    assert main(sweep(base, done)) == 0
    lines = errors(capsys)
    assert lines == [
        f"warning: {b}: values, seed: not those of the run of this id; computed again"
    ]


def test_a_row_pasted_into_results_csv_is_not_counted(done, capsys):
    csv_path = done / "results.csv"
    good = csv_path.read_text()
    last = good.splitlines()[-1]
    csv_path.write_text(good + last + "\n" + last.replace(",1,", ",7,", 1) + "\n")
    assert main(["sweep", "table", str(done), "--format", "csv"]) == 0
    out = capsys.readouterr()
    assert "does not match the run files; rebuilt" in out.err
    assert csv_path.read_text() == good
    # the table counts 2 runs per value of recovery.beta, not 3
    assert all(",2," in ln for ln in out.out.splitlines()[1:]), out.out


def test_an_edited_row_of_a_run_file_is_refused(done, base, capsys):
    run = sorted((done / "runs").glob("*.json"))[0]
    doc = json.loads(run.read_text())
    doc["row"]["status"] = "=HYPERLINK(1)"
    run.write_text(json.dumps(doc), encoding="utf-8")
    assert main(sweep(base, done)) == 0
    assert "row.status: not one of ok, diverged, invalid, error" in errors(capsys)[0]


# ------------------------------------------------------------------ N14: one writer
def test_a_second_sweep_into_a_store_in_use_is_refused(done, base, capsys):
    spec = build_spec(base, grid=["recovery.beta=1,2"], seeds="0:2")
    first = Store(done)
    first.lock()  # a sweep under way in another process holds the same lock
    try:
        pid = os.getpid()
        assert main(sweep(base, done)) == 2
        lines = errors(capsys)
        assert lines == [
            f"error: {done}: another sandbox sweep is writing into it (process {pid})"
            "; wait for it to end, or use another --out"
        ]
    finally:
        first.close()
    assert main(sweep(base, done)) == 0  # free again
    assert spec.count() == 4


def test_the_lock_is_across_processes(done, base):
    import subprocess
    import sys
    import time

    from helpers import REPO

    code = (
        "import sys, time; from sandbox.study.store import Store; "
        f"s = Store({str(done)!r}); s.lock(); print('locked', flush=True); "
        "time.sleep(30)"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    holder = subprocess.Popen(
        [sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        start = time.perf_counter()
        got = subprocess.run(
            [sys.executable, "-m", "sandbox", *sweep(base, done)],
            env=env,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert got.returncode == 2 and time.perf_counter() - start < 10
        assert f"process {holder.pid}" in got.stderr
        assert len(got.stderr.splitlines()) == 1
    finally:
        holder.kill()
        holder.communicate()


def test_a_store_with_only_a_lock_file_is_still_a_new_store(tmp_path, base):
    out = tmp_path / "out"
    out.mkdir()
    (out / ".lock").write_text("")  # left by a sweep killed as it started
    assert main(sweep(base, out)) == 0


# ------------------------------------------------------------------ N12, N13: writes
def failing_replace(exc: OSError):
    def replace(src, dst):
        raise exc

    return replace


@pytest.mark.parametrize(
    ("exc", "reason"),
    [
        (OSError(errno.EROFS, "Read-only file system"), "Read-only file system"),
        (OSError(errno.ENOSPC, "No space left on device"), "No space left on device"),
        (
            PermissionError(errno.EACCES, "Permission denied", "/x/.results.csv.1.tmp"),
            "Permission denied",
        ),
    ],
)
def test_a_failed_write_names_the_users_file(
    done, base, capsys, monkeypatch, exc, reason
):
    monkeypatch.setattr(store_module.os, "replace", failing_replace(exc))
    assert main(sweep(base, done, "--retry-failed")) == 1
    lines = errors(capsys)
    assert lines == [f"error: {done / 'sweep.json'}: cannot write ({reason})"]
    assert not [p for p in done.rglob(".*.tmp")]


def test_a_full_disk_while_storing_names_the_run_file(
    tmp_path, base, capsys, monkeypatch
):
    out = tmp_path / "out"
    real = Path.write_text

    def full(self, data, *args, **kw):  # a run file's first bytes, then ENOSPC
        if self.parent.name == "runs":
            real(self, data[:10], *args, **kw)
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, data, *args, **kw)

    monkeypatch.setattr(Path, "write_text", full)
    assert main(sweep(base, out)) == 1
    lines = errors(capsys)
    assert len(lines) == 1 and lines[0].startswith(f"error: {out / 'runs'}/"), lines
    assert lines[0].endswith(".json: cannot write (No space left on device)")
    assert not list(out.rglob(".*.tmp"))  # no temporary left behind
    assert not list((out / "runs").glob("*.json"))  # nor a partial run file


def test_plot_writes_every_figure_atomically(done, monkeypatch, capsys):
    # a kill while a figure is drawn leaves the previous figure, never a partial one
    import matplotlib.figure

    figs = done / "figs"
    assert main(["sweep", "plot", str(done), "--out", str(figs)]) == 0
    before = {p.name: p.read_bytes() for p in figs.glob("*.png")}
    assert before and all(b[:8] == b"\x89PNG\r\n\x1a\n" for b in before.values())

    def killed(self, fname, **kw):
        Path(fname).write_bytes(b"")  # the first bytes of a figure, then SIGKILL
        raise KeyboardInterrupt

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", killed)
    assert main(["sweep", "plot", str(done), "--out", str(figs)]) == 130
    after = {p.name: p.read_bytes() for p in figs.glob("*.png")}
    assert after == before
    # no temporary file left; only the record of what sweep plot wrote there
    assert [p.name for p in figs.glob(".*")] == [".sandbox-outputs.json"]
