"""Camera benchmarks (JSON on stdout).

1. In-process simulated source at full 2448×2048 Mono16 (default rig, IMX250): sustained frames/s
   with per-frame ROI mean and variance through the `Camera` interface, frames dropped, and the
   statistics' share of the frame period (targets: ≥ 100 fps (issue 26), 0 dropped, ≤ 20 %).
2. Aravis on loopback against ``uwlab sim camera --gige`` (a subprocess) at the simulated
   camera's default size: achieved frames/s.

Usage: python benchmarks/bench_camera.py [--frames N] [--gige-frames N] [--no-gige]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

import numpy as np

from uwlab.drivers.camera import Policy, open_camera

TARGET_FPS = 100.0


def bench_sim(n_frames: int) -> dict:
    with open_camera("sim") as cam:
        cam.pixel_format = "Mono16"
        cam.exposure_us = 100.0
        width, height = cam.info.sensor_width, cam.info.sensor_height
        cam.set_roi(0, 0, width, height)
        roi = (slice(height // 2 - 256, height // 2 + 256), slice(width // 2 - 256, width // 2 + 256))
        stats_s, last_id, dropped = 0.0, None, 0
        list(cam.stream(3))
        t0 = time.perf_counter()
        for frame in cam.stream(n_frames):
            s0 = time.perf_counter()
            patch = frame.image[roi]
            float(patch.mean()), float(patch.var())
            stats_s += time.perf_counter() - s0
            dropped += 0 if last_id is None else frame.frame_id - last_id - 1
            last_id = frame.frame_id
        elapsed = time.perf_counter() - t0
        cam.stop()
    fps = n_frames / elapsed
    return {
        "source": "sim in-process",
        "width": width,
        "height": height,
        "pixel_format": "Mono16",
        "frames": n_frames,
        "fps": round(fps, 1),
        "dropped": dropped + cam.stats.discarded,
        "stats_fraction_of_period": round(stats_s / elapsed, 4),
        "target_fps": TARGET_FPS,
        "meets_target": fps >= TARGET_FPS and dropped == 0 and stats_s / elapsed <= 0.2,
    }


def bench_gige(n_frames: int, address: str = "127.0.0.77") -> dict:
    proc = subprocess.Popen(
        [sys.executable, "-m", "uwlab.cli.main", "sim", "camera", "--gige", "--json", "--address", address],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        info = json.loads(proc.stdout.readline())
        with open_camera("aravis", info["address"], policy=Policy(timeout_s=5.0)) as cam:
            cam.exposure_us = 100.0
            list(cam.stream(2))
            t0 = time.perf_counter()
            frames = [f.frame_id for f in cam.stream(n_frames)]
            elapsed = time.perf_counter() - t0
            return {
                "source": "aravis gige loopback",
                "width": int(cam.transport.get("Width")),
                "height": int(cam.transport.get("Height")),
                "pixel_format": cam.pixel_format,
                "frames": n_frames,
                "fps": round(n_frames / elapsed, 2),
                "dropped": int(np.sum(np.diff(frames) - 1)),
                "discarded": cam.stats.discarded,
            }
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--gige-frames", type=int, default=30)
    parser.add_argument("--no-gige", action="store_true")
    args = parser.parse_args()
    results = {"sim": bench_sim(args.frames)}
    if not args.no_gige:
        results["aravis_gige"] = bench_gige(args.gige_frames)
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
