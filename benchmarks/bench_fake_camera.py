"""Aravis's fake camera beside the simulated camera (JSON on stdout).

Both grab N frames (default 100) at their full sensor size through the same `Camera` interface: ``Fake_1``
(2048 × 2048, its frame rate raised to its maximum so that its image generator, not its clock, sets the pace) and
the in-process simulated camera of the default rig (IMX250, 2448 × 2048), each in Mono8 and Mono16 (and Fake_1 in
BayerRG8). Reported: frames per second and the mean of the last frame (a check that real images came through).

Usage: python benchmarks/bench_fake_camera.py [--frames N]
"""

from __future__ import annotations

import argparse
import json
import time

from uwlab.drivers.camera import Policy, open_camera


def bench(backend: str, device: str | None, pixel_format: str, n_frames: int) -> dict:
    with open_camera(backend, device, policy=Policy(timeout_s=10.0)) as cam:
        cam.pixel_format = pixel_format
        width, height = cam.info.sensor_width, cam.info.sensor_height
        cam.set_roi(0, 0, width, height)
        if backend == "aravis":
            bounds = cam.transport.bounds("AcquisitionFrameRate")
            cam.frame_rate_hz = bounds[1]
        else:
            cam.exposure_us = 100.0
        list(cam.stream(2))
        t0 = time.perf_counter()
        for frame in cam.stream(n_frames):
            last = frame
        elapsed = time.perf_counter() - t0
        cam.stop()
        discarded = cam.stats.discarded
    return {
        "camera": f"{backend}:{cam.info.device_id}",
        "model": cam.info.model,
        "width": width,
        "height": height,
        "pixel_format": pixel_format,
        "frames": n_frames,
        "fps": round(n_frames / elapsed, 1),
        "discarded": discarded,
        "last_frame_mean_dn": round(float(last.image.mean()), 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100)
    args = parser.parse_args()
    results = [bench("aravis", "Fake_1", fmt, args.frames) for fmt in ("Mono8", "Mono16", "BayerRG8")]
    results += [bench("sim", None, fmt, args.frames) for fmt in ("Mono8", "Mono16")]
    print(json.dumps({"benchmark": "fake_camera", "results": results}, indent=1))


if __name__ == "__main__":
    main()
