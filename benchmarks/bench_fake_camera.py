"""Acquisition through the `Camera` interface against the backends' own fetch loops (JSON on stdout).

1. Overhead (issue 26's target: ≤ 10 % over the backend's own fetch loop at full sensor size). For each case, the
   same device, pixel format and size is read N frames (default 100) by the backend's own loop, with no uwlab layer,
   and through `Camera.stream`, alternately, ``--repeats`` times (default 5); medians are reported:

   * Aravis's fake camera ``Fake_1`` (2048 × 2048, frame rate raised to its maximum so that its image generator, not
     its clock, sets the pace), Mono8, Mono16 and BayerRG8. Own loop: ``Aravis.Camera`` → stream with as many
     buffers as the uwlab backend queues, ``timeout_pop_buffer``, ``get_data``, ``np.frombuffer`` into a
     (height, width) image, ``push_buffer``.
   * harvesters on the genicam wheel's GenTL test producer ``viky.cti`` (``VikyTL_DEV_green``, Mono8 at its largest
     size, 800 × 800, and its fastest rate, 200 Hz). Own loop: ``with ia.fetch() as buffer`` and the component's
     data reshaped and copied (the buffer is queued back on leaving the block, so a frame kept beyond it is a copy
     — the one copy uwlab makes too).

   Reported per case: frames per second of both loops, the overhead (``uwlab_s / own_s - 1`` in %, and the extra
   wall time per frame in ms) and the consumer thread's CPU time per frame in both loops (``time.thread_time``:
   what the loop itself costs, whatever paces the source — Viky's clock, Fake_1's image generator in its own
   thread).
2. The in-process simulated camera of the default rig (IMX250, 2448 × 2048) in Mono8, Mono12p (packed by the
   simulated device, unpacked by `Camera`) and Mono16 through `Camera` (it has no loop of its own): frames per second
   and the consumer thread's CPU time per frame, rendering included (medians of the repeats).

Usage: python benchmarks/bench_fake_camera.py [--frames N] [--repeats R] [--only aravis|harvesters|sim]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from uwlab.drivers.camera import Policy, open_camera

FAKE_ID = "Fake_1"
VIKY_ID = "VikyTL_DEV_green"
VIKY_RATE_HZ = 200.0
WARMUP = 3


def timed(grab: Callable[[], np.ndarray], n_frames: int) -> dict:
    """Run ``grab`` ``n_frames`` times after a warm-up: wall and consumer-thread CPU seconds, the last image."""
    for _ in range(WARMUP):
        grab()
    t0, c0 = time.perf_counter(), time.thread_time()
    for _ in range(n_frames):
        last = grab()
    return {"wall_s": time.perf_counter() - t0, "cpu_s": time.thread_time() - c0, "mean_dn": float(last.mean())}


# -- the backends' own loops ------------------------------------------------------------------------------------


@contextmanager
def aravis_own(pixel_format: str) -> Iterator[tuple[Callable[[], np.ndarray], tuple[int, int]]]:
    import gi

    gi.require_version("Aravis", "0.8")
    from gi.repository import Aravis

    from uwlab.drivers.camera.aravis_backend import N_BUFFERS

    Aravis.enable_interface("Fake")
    camera = Aravis.Camera.new(FAKE_ID)
    camera.set_pixel_format_from_string(pixel_format)
    width, height = camera.get_sensor_size()
    camera.set_region(0, 0, width, height)
    camera.set_frame_rate(camera.get_frame_rate_bounds()[1])
    stream = camera.create_stream(None, None)
    payload = camera.get_payload()
    for _ in range(N_BUFFERS):
        stream.push_buffer(Aravis.Buffer.new_allocate(payload))
    dtype = np.uint16 if pixel_format.endswith("16") else np.uint8
    camera.start_acquisition()

    def grab() -> np.ndarray:
        buf = stream.timeout_pop_buffer(10_000_000)
        image = np.frombuffer(buf.get_data(), dtype).reshape(height, width)
        stream.push_buffer(buf)
        return image

    try:
        yield grab, (width, height)
    finally:
        camera.stop_acquisition()


@contextmanager
def harvesters_own(pixel_format: str) -> Iterator[tuple[Callable[[], np.ndarray], tuple[int, int]]]:
    from harvesters.core import Harvester

    from uwlab.drivers.camera.harvesters_backend import bundled_producers

    h = Harvester()
    h.add_file(str(bundled_producers()[0]))
    h.update()
    ia = h.create({"id_": VIKY_ID})
    nm = ia.remote_device.node_map
    nm.PixelFormat.value = pixel_format
    nm.Width.value, nm.Height.value = nm.Width.max, nm.Height.max
    nm.AcquisitionFrameRate.value = VIKY_RATE_HZ
    width, height = int(nm.Width.value), int(nm.Height.value)
    ia.start()

    def grab() -> np.ndarray:
        with ia.fetch(timeout=10.0) as buffer:
            component = buffer.payload.components[0]
            return component.data.reshape(component.height, component.width).copy()

    try:
        yield grab, (width, height)
    finally:
        ia.stop()
        ia.destroy()
        h.reset()


# -- the same through `Camera` ------------------------------------------------------------------------------------


@contextmanager
def through_camera(backend: str, pixel_format: str) -> Iterator[tuple[Callable[[], np.ndarray], tuple[int, int]]]:
    device, options = {"aravis": (FAKE_ID, {}), "harvesters": (VIKY_ID, {"fake": True}), "sim": (None, {})}[backend]
    with open_camera(backend, device, policy=Policy(timeout_s=10.0), **options) as cam:
        cam.pixel_format = pixel_format
        width, height = cam.info.sensor_width, cam.info.sensor_height
        if not width:  # Viky has no SensorWidth/WidthMax: its largest ROI
            width, height = (int(cam.transport.bounds(name)[1]) for name in ("Width", "Height"))  # type: ignore[index]
        cam.set_roi(0, 0, width, height)
        if backend == "aravis":
            cam.frame_rate_hz = cam.transport.bounds("AcquisitionFrameRate")[1]  # type: ignore[index]
        elif backend == "harvesters":
            cam.frame_rate_hz = VIKY_RATE_HZ
        else:
            cam.exposure_us = 100.0
        frames = cam.stream()

        def grab() -> np.ndarray:
            return next(frames).image

        try:
            yield grab, (width, height)
        finally:
            cam.stop()
            if cam.stats.discarded:
                raise RuntimeError(f"{backend}: {cam.stats.discarded} incomplete frames discarded")


def run(loop: Callable[[str], Any], pixel_format: str, n_frames: int) -> dict:
    with loop(pixel_format) as (grab, size):
        return timed(grab, n_frames) | {"size": size}


def median(runs: list[dict], key: str) -> float:
    return statistics.median(r[key] for r in runs)


def compare(backend: str, own: Callable[[str], Any], pixel_format: str, n_frames: int, repeats: int) -> dict:
    """Own loop and `Camera` alternately, ``repeats`` times each; medians."""
    mine: list[dict] = []
    theirs: list[dict] = []
    for _ in range(repeats):
        theirs.append(run(own, pixel_format, n_frames))
        mine.append(run(lambda fmt: through_camera(backend, fmt), pixel_format, n_frames))
    own_s, uwlab_s = median(theirs, "wall_s"), median(mine, "wall_s")
    width, height = mine[0]["size"]
    return {
        "camera": f"{backend}:{FAKE_ID if backend == 'aravis' else VIKY_ID}",
        "width": width,
        "height": height,
        "pixel_format": pixel_format,
        "frames": n_frames,
        "repeats": repeats,
        "own_fps": round(n_frames / own_s, 1),
        "uwlab_fps": round(n_frames / uwlab_s, 1),
        "overhead_pct": round(100.0 * (uwlab_s / own_s - 1.0), 1),
        "overhead_ms_per_frame": round(1e3 * (uwlab_s - own_s) / n_frames, 3),
        "own_cpu_ms_per_frame": round(1e3 * median(theirs, "cpu_s") / n_frames, 3),
        "uwlab_cpu_ms_per_frame": round(1e3 * median(mine, "cpu_s") / n_frames, 3),
        "own_fps_runs": [round(n_frames / r["wall_s"], 1) for r in theirs],
        "uwlab_fps_runs": [round(n_frames / r["wall_s"], 1) for r in mine],
        "same_images": abs(theirs[-1]["mean_dn"] - mine[-1]["mean_dn"]) <= 0.05 * max(theirs[-1]["mean_dn"], 1.0),
    }


def sim(pixel_format: str, n_frames: int, repeats: int) -> dict:
    runs = [run(lambda fmt: through_camera("sim", fmt), pixel_format, n_frames) for _ in range(repeats)]
    width, height = runs[0]["size"]
    return {
        "camera": "sim:sim0",
        "width": width,
        "height": height,
        "pixel_format": pixel_format,
        "frames": n_frames,
        "repeats": repeats,
        "fps": round(n_frames / median(runs, "wall_s"), 1),
        "cpu_ms_per_frame": round(1e3 * median(runs, "cpu_s") / n_frames, 3),
        "last_frame_mean_dn": round(runs[-1]["mean_dn"], 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--only", choices=("aravis", "harvesters", "sim"))
    args = parser.parse_args()
    n, r = args.frames, args.repeats
    overhead, results = [], []
    if args.only in (None, "aravis"):
        overhead += [compare("aravis", aravis_own, fmt, n, r) for fmt in ("Mono8", "Mono16", "BayerRG8")]
    if args.only in (None, "harvesters"):
        overhead.append(compare("harvesters", harvesters_own, "Mono8", n, r))
    if args.only in (None, "sim"):
        results += [sim(fmt, n, r) for fmt in ("Mono8", "Mono12p", "Mono16")]
    print(json.dumps({"benchmark": "fake_camera", "overhead": overhead, "sim": results}, indent=1))


if __name__ == "__main__":
    main()
