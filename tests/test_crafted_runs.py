"""Crafted or damaged run directories are refused before anything reads their arrays.

Each case starts from a valid run directory and breaks its ``run.npz`` one way (shapes,
dtypes, members, metadata, sizes that would inflate far beyond the file); ``sandbox
render`` and ``sandbox plot`` must answer ``not a valid run directory: ...`` with exit
status 2 and no traceback, without allocating what the file claims.
"""

from __future__ import annotations

import io
import json
import struct
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from sandbox.cli import main
from sandbox.errors import OutputError
from sandbox.run.output import load_run_dir

SCENARIO = {
    "name": "tiny",
    "duration": 0.3,
    "reference": {"type": "circle", "center": [0, 0], "radius": 5, "speed": 1},
    "formation": {"law": "rotating"},
    "vehicles": [
        {"name": "leader", "pose": [5, 0, 1.5708], "leader": True},
        {"name": "red", "pose": [4, -1, 1.5708], "offset": [-1, 1]},
    ],
}


@pytest.fixture(scope="module")
def valid(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("valid")
    src = root / "tiny.yaml"
    src.write_text(json.dumps(SCENARIO), encoding="utf-8")
    assert main(["run", str(src), "--out", str(root / "run")]) == 0
    return root / "run"


def arrays_of(run_dir: Path) -> dict[str, np.ndarray]:
    with np.load(run_dir / "run.npz") as data:
        return {k: data[k] for k in data.files}


def npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, array)
    return buf.getvalue()


def lying_header(shape: tuple[int, ...]) -> bytes:
    """A float64 .npy header claiming ``shape``, followed by 16 bytes of data."""
    head = repr({"descr": "<f8", "fortran_order": False, "shape": shape}).encode()
    head = head + b" " * (63 - (len(head) + 10) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(head)) + head + b"\0" * 16


def with_meta(change: Callable[[dict], None]) -> Callable[[dict], None]:
    def edit(arrays: dict) -> None:
        meta = json.loads(str(arrays["meta"]))
        change(meta)
        arrays["meta"] = np.array(json.dumps(meta))

    return edit


#: name -> (how the arrays are changed, or raw members to write; text expected)
CASES: dict[str, tuple[Callable[[dict], None], str]] = {
    "pose_wrong_shape": (
        lambda a: a.update(pose=a["pose"][:, :, :2]),
        "pose: shape",
    ),
    "pose_fewer_samples": (
        lambda a: a.update(pose=a["pose"][:-1]),
        "pose: shape",
    ),
    "more_names_than_vehicles": (
        with_meta(lambda m: m.update(names=[*m["names"], "ghost"])),
        "3 names for 2 vehicles",
    ),
    "zero_samples": (
        lambda a: a.update(
            {k: v[:0] for k, v in a.items() if k not in ("meta", "diameter")}
        ),
        "no recorded samples",
    ),
    "mode_as_float": (
        lambda a: a.update(mode=a["mode"].astype(float)),
        "mode: dtype float64",
    ),
    "missing_member": (lambda a: a.pop("chi"), "no chi"),
    "unknown_member": (lambda a: a.update(extra=np.zeros(2)), "unknown 'extra.npy'"),
    "meta_not_json": (lambda a: a.update(meta=np.array("{nope")), "meta: not JSON"),
    "leader_out_of_range": (
        with_meta(lambda m: m.update(leader=7)),
        "leader 7 is not a vehicle index",
    ),
    "bad_event": (
        with_meta(lambda m: m.update(events=[["x"]])),
        "an event is not",
    ),
    "bad_status": (with_meta(lambda m: m.update(status="fine")), "unknown status"),
}


def write_npz(path: Path, members: dict[str, bytes]) -> None:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(f"{name}.npy", data)


def craft(valid: Path, tmp_path: Path, edit: Callable[[dict], None]) -> Path:
    out = tmp_path / "run"
    out.mkdir()
    for f in valid.iterdir():
        if f.is_file() and f.name != "run.npz":
            (out / f.name).write_bytes(f.read_bytes())
    arrays = arrays_of(valid)
    edit(arrays)
    write_npz(out / "run.npz", {k: npy_bytes(v) for k, v in arrays.items()})
    return out


def refused(run_dir: Path, text: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(OutputError) as info:
        load_run_dir(run_dir)
    assert str(info.value).startswith(f"not a valid run directory: {run_dir} (")
    assert text in str(info.value)
    for argv in (
        ["render", str(run_dir), "--gif", str(run_dir.parent / "x.gif")],
        ["plot", str(run_dir)],
    ):
        assert main(argv) == 2  # invalid input
        err = capsys.readouterr().err
        assert err.startswith("error: not a valid run directory: ")
        assert "Traceback" not in err
    assert not (run_dir.parent / "x.gif").exists()
    assert not (run_dir / "figures").exists()


def test_the_valid_run_loads(valid: Path) -> None:
    assert load_run_dir(valid).names == ["leader", "red"]


@pytest.mark.parametrize("case", list(CASES))
def test_a_crafted_run_is_refused_by_render_and_plot(
    case: str, valid: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    edit, text = CASES[case]
    refused(craft(valid, tmp_path, edit), text, capsys)


def test_a_header_bomb_is_refused_before_inflating(
    valid: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """pose claims 10^12 samples (8 TB) in a few bytes: refused from its header."""
    run_dir = craft(valid, tmp_path, lambda a: None)
    members = {k: npy_bytes(v) for k, v in arrays_of(valid).items()}
    members["pose"] = lying_header((10**12, 2, 3))
    write_npz(run_dir / "run.npz", members)
    refused(run_dir, "pose: its header claims 48,000,000,000,000 bytes", capsys)


def test_a_compression_bomb_is_refused_from_the_zip_directory(
    valid: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A member whose directory entry claims far more than DEFLATE can give."""
    run_dir = craft(valid, tmp_path, lambda a: None)
    npz = run_dir / "run.npz"
    data = bytearray(npz.read_bytes())
    with zipfile.ZipFile(io.BytesIO(bytes(data))) as zf:
        info = zf.getinfo("pose.npy")
    # Patch the central directory's uncompressed size of pose.npy to 4 GB - 1.
    entry = data.rfind(b"PK\x01\x02", 0, data.rfind(b"pose.npy"))
    struct.pack_into("<I", data, entry + 24, 0xFFFFFFFE)
    npz.write_bytes(bytes(data))
    assert info.compress_size < 0xFFFFFFFE // 1100
    refused(run_dir, "a compression bomb", capsys)


def test_scenario_and_arrays_naming_other_vehicles_are_refused(
    valid: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = craft(valid, tmp_path, with_meta(lambda m: m.update(names=["a", "b"])))
    refused(run_dir, "scenario.yaml names other vehicles", capsys)


def test_a_truncated_or_foreign_npz_is_refused(
    valid: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = craft(valid, tmp_path, lambda a: None)
    whole = (run_dir / "run.npz").read_bytes()
    (run_dir / "run.npz").write_bytes(whole[: len(whole) // 2])
    refused(run_dir, "damaged", capsys)
    (run_dir / "run.npz").write_bytes(b"\x89PNG\r\n")
    refused(run_dir, "damaged", capsys)
