"""Benchmark of ``sandbox.render``: drawing and GIF encoding time per frame.

Run with ``python benchmarks/bench_render.py``. It builds synthetic runs (no simulator
needed): 10 vehicles circling a drifting reference, with trails, slots, obstacles, a
failure, avoidance episodes and collisions; and 1,000 vehicles on concentric circles.
Per frame at 640 px it times the drawing of the palette-index canvases ``write_gif``
uses, the GIF encoding alone (imageio + stream assembly), ``write_gif`` end to end, and
``render_frames`` (drawing + RGB conversion), and compares ``write_gif`` with the 5 ms
per frame target (10 vehicles). Not a test.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sandbox.render import animation as render  # noqa: E402
from sandbox.run.record import MODE_AVOID, MODE_FAILED, CollisionEvent, Run  # noqa: E402

TARGET_MS = 5.0  # [ms] per frame, 10 vehicles at 640 px, drawing + encoding


def circling_run(n: int, duration: float = 20.0, dt: float = 0.02) -> Run:
    """Synthetic run: ``n`` vehicles on circles around a drifting centre.

    Parameters
    ----------
    n : int
        Number of vehicles.
    duration : float [s]
    dt : float [s]
        Recording interval.

    Returns
    -------
    Run
    """
    t = np.arange(0.0, duration + dt / 2, dt)
    T = len(t)
    k = np.arange(n)
    ring = 1 + k // 40  # [-] concentric rings of 40 vehicles for large n
    radius = 2.0 + 1.5 * ring  # [m]
    phase = 2 * np.pi * (k % 40) / min(n, 40)
    omega = 0.3  # [rad/s]
    ang = phase[None, :] + omega * t[:, None]
    centre = np.stack((0.2 * t, 0.5 * np.sin(0.2 * t)), -1)  # [m]
    x = centre[:, None, 0] + radius * np.cos(ang)
    y = centre[:, None, 1] + radius * np.sin(ang)
    heading = ang + np.pi / 2
    pose = np.stack((x, y, heading), -1)
    cmd = np.stack(
        (np.broadcast_to(radius * omega, (T, n)), np.full((T, n), omega)), -1
    )
    slot = pose[:, :, :2] + 0.1 * np.sin(t)[:, None, None]
    mode = np.zeros((T, n), dtype=np.int8)
    failed = np.zeros((T, n), dtype=bool)
    mode[(t > 5) & (t < 7), : min(n, 3)] = MODE_AVOID
    failed[t >= 12, n // 2] = True
    mode[t >= 12, n // 2] = MODE_FAILED
    palette = [
        "blue",
        "red",
        "green",
        "orange",
        "purple",
        "#1f77b4",
        "teal",
        "gold",
        "magenta",
        "brown",
    ]
    names = [f"v{i}" for i in range(n)]
    events = [
        CollisionEvent(float(s), names[0], names[1], "vehicle_vehicle") for s in (3, 9)
    ]
    events.append(CollisionEvent(14.0, names[2], "rock", "vehicle_obstacle"))
    path = centre[::10].tolist()
    return Run(
        t=t,
        pose=pose,
        cmd=cmd,
        chi=cmd.copy(),
        slot=slot,
        target=slot.copy(),
        mode=mode,
        failed=failed,
        reference=centre,
        names=names,
        colors=[palette[i % len(palette)] for i in range(n)],
        diameter=np.full(n, 0.5),
        leader=0,
        events=events,
        info={
            "obstacles": [
                {"type": "circle", "center": [2.0, 5.0], "radius": 0.8, "name": "rock"},
                {
                    "type": "polygon",
                    "points": [[-6, -6], [-4, -6], [-4, -5], [-6, -5]],
                    "name": "box",
                },
            ],
            "recovery": {"strategy": "continuous", "R": 1.5, "r": 0.75},
            "reference_path": path,
            "scenario_name": f"bench-{n}",
        },
    )


class Clock:
    """Wall-clock and CPU time of a block [s] (CPU time is immune to other load)."""

    def __enter__(self) -> Clock:
        self.wall0, self.cpu0 = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc: object) -> None:
        self.wall = time.perf_counter() - self.wall0
        self.cpu = time.process_time() - self.cpu0


def bench(run: Run, label: str, *, fps: float = 25.0, size: int = 640, **kw) -> dict:
    """Time drawing, encoding and ``write_gif`` of one run [ms per frame]."""
    plan = render.frame_plan(run, fps)
    count = len(plan)
    options = {"zones": False, "follow": None, "trail_seconds": 3.0} | kw

    with Clock() as rgb:
        for _ in render.render_frames(run, fps=fps, size=size, **options):
            pass

    scene, frames = render.indexed_frames(
        run, plan, size=size, speed=1.0, fps=fps, **options
    )
    with Clock() as draw:
        canvases = list(frames)

    with tempfile.TemporaryDirectory() as tmp:
        with Clock() as encode, open(Path(tmp) / "enc.gif", "wb") as fh:
            stream = render._GifStream(fh, size, size, scene.rgb)
            durations = plan.durations_ms.tolist()
            for i in range(0, count, render.GIF_CHUNK):
                chunk = slice(i, i + render.GIF_CHUNK)
                stream.add(canvases[chunk], durations[chunk])
            stream.close()
        del canvases

        gif = Path(tmp) / "run.gif"
        with Clock() as total:
            render.write_gif(run, gif, fps=fps, size=size, **options)
        kib = gif.stat().st_size / 1024

    def ms(c: Clock) -> float:
        return c.cpu / count * 1e3

    return {
        "label": label,
        "frames": count,
        "draw": ms(draw),
        "encode": ms(encode),
        "total": ms(total),
        "wall": total.wall / count * 1e3,
        "rgb": ms(rgb),
        "kib": kib,
        "seconds": float(run.t[-1] - run.t[0]),
    }


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print a table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0, help="run length [s]")
    parser.add_argument("--size", type=int, default=640, help="frame size [px]")
    args = parser.parse_args(argv)
    ten = circling_run(10, args.duration)
    rows = [
        bench(ten, "10 vehicles", size=args.size),
        bench(ten, "10, zones+follow", size=args.size, zones=True, follow="leader"),
        bench(
            circling_run(1000, min(args.duration, 4.0)), "1000 vehicles", size=args.size
        ),
    ]
    head = (
        f"{'run':<18}{'frames':>7}{'draw':>8}{'encode':>8}{'total':>8}"
        f"{'(wall)':>8}{'rgb':>8}{'KiB/min':>9}"
    )
    print(f"CPU ms per frame at {args.size} px, 25 fps")
    print("  draw:   palette-index canvases (what write_gif encodes)")
    print("  encode: imageio (Pillow) GIF encoding + stream assembly")
    print("  total:  write_gif end to end (draw + encode); (wall): same, wall clock")
    print("  rgb:    render_frames (draw + RGB conversion)")
    print("  KiB/min: GIF size per minute of run")
    print(head)
    print("-" * len(head))
    for r in rows:
        print(
            f"{r['label']:<18}{r['frames']:>7}{r['draw']:>8.2f}{r['encode']:>8.2f}"
            f"{r['total']:>8.2f}{r['wall']:>8.2f}{r['rgb']:>8.2f}"
            f"{r['kib'] * 60 / r['seconds']:>9.0f}"
        )
    got = rows[0]["total"]
    verdict = "met" if got <= TARGET_MS else "NOT met"
    print(
        f"target: <= {TARGET_MS:g} ms per frame (write_gif, 10 vehicles, "
        f"{args.size} px): {got:.2f} ms CPU -> {verdict}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
