"""Benchmark of the scenario loader on hostile files: time and peak memory.

Run with ``python benchmarks/bench_loader.py``. It times, in one process:

- a 4-line file asking for 20,000 vehicles 1 mm apart (rejected: they overlap), and
  the same platoon at a spacing that passes (accepted);
- a 1.5 MB scenario (25,000 listed vehicles) parsed by the loader's YAML parser
  (libyaml's C parser when PyYAML has it) and by PyYAML's pure-Python ``SafeLoader``,
  reported as a ratio;
- ``load_scenario`` of that file end to end;
- files of 1,000, 3,000 and 10,000 one-vehicle platoons (``platoons:``), whose time
  per platoon stays the same (the loader is linear in the platoons; v0.3 took 7.8 /
  22 / 52 s for 500 / 1,000 / 2,000 and did not finish 10,000), timed once each.

Peak memory is Python's traced allocation peak (``tracemalloc``). Not a test.
"""

from __future__ import annotations

import sys
import tempfile
import time
import tracemalloc
import warnings
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sandbox import scenario as sc  # noqa: E402
from sandbox.errors import SandboxWarning, ScenarioError  # noqa: E402


def measure(fn) -> tuple[float, float]:
    """Wall time [s] of one call of ``fn``, and its traced peak memory [MB] (a second
    call: tracing slows Python down several times)."""
    t0 = time.perf_counter()
    try:
        fn()
    except ScenarioError:
        pass
    dt = time.perf_counter() - t0
    tracemalloc.start()
    try:
        fn()
    except ScenarioError:
        pass
    peak = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    return dt, peak


def main() -> None:
    """Print the table."""
    tmp = Path(tempfile.mkdtemp())
    point = "reference: {type: point, position: [0, 0]}\n"
    crowded = tmp / "crowded.yaml"
    crowded.write_text("platoon: {count: 20000, spacing: 0.001}\n" + point)
    spaced = tmp / "spaced.yaml"
    spaced.write_text(
        "platoon: {count: 20000, spacing: 1}\nformation: {law: virtual}\n" + point
    )
    rows = [
        f"  - {{name: v{i}, pose: [{i * 2}, 0, 0], offset: [{i * 2}, 0]}}"
        for i in range(25_000)
    ]
    big = tmp / "big.yaml"
    big.write_text(
        "formation: {law: virtual}\n" + point + "vehicles:\n" + "\n".join(rows) + "\n"
    )
    text = big.read_text()

    def parse(loader: type) -> None:
        parser = loader(text)
        parser.construct_document(parser.get_single_node())
        parser.dispose()

    print(f"big file: {len(text) / 1e6:.2f} MB; libyaml: {yaml.__with_libyaml__}")
    print(f"{'case':52s} {'time [s]':>9s} {'peak [MB]':>10s}")
    results = {}
    for label, fn in (
        ("20,000 vehicles 1 mm apart (rejected)", lambda: sc.load_scenario(crowded)),
        ("20,000 vehicles 1 m apart (accepted)", lambda: sc.load_scenario(spaced)),
        (
            "1.5 MB, the loader's parser (compose + construct)",
            lambda: parse(sc.YAMLLoader),
        ),
        (
            "1.5 MB, pure-Python SafeLoader (compose + construct)",
            lambda: parse(yaml.SafeLoader),
        ),
        ("1.5 MB, load_scenario end to end", lambda: sc.load_scenario(big)),
    ):
        results[label] = measure(fn)
        print(f"{label:52s} {results[label][0]:9.3f} {results[label][1]:10.1f}")
    keys = list(results)
    ratio = results[keys[3]][0] / results[keys[2]][0]
    print(f"pure-Python / loader parser time: {ratio:.1f}x")
    print(
        f"\n{'one-vehicle platoons':22s} {'file [MB]':>9s} {'time [s]':>9s} "
        f"{'per platoon [ms]':>17s}"
    )
    for count in (1_000, 3_000, 10_000):
        path = platoons_file(tmp, count)
        start = time.perf_counter()
        with warnings.catch_warnings():  # each platoon's own (tunnelling)
            warnings.simplefilter("ignore", SandboxWarning)
            sc.load_scenario(path)
        took = time.perf_counter() - start
        size = path.stat().st_size / 1e6
        print(f"{count:22,d} {size:9.2f} {took:9.2f} {1e3 * took / count:17.2f}")


def platoons_file(folder: Path, count: int) -> Path:
    """A file of ``count`` platoons of one vehicle each, 2 m apart on a line."""
    rows = [
        f"  - {{name: p{i}, vehicles: [{{name: v{i}, pose: [{2 * i}, 0, 0], "
        "leader: true}]}"
        for i in range(count)
    ]
    path = folder / f"platoons_{count}.yaml"
    path.write_text(
        "duration: 5\nreference: {type: point, position: [0, 0]}\n"
        "formation: {law: rotating}\nplatoons:\n" + "\n".join(rows) + "\n"
    )
    return path


if __name__ == "__main__":
    main()
