"""EMVA 1288 streaming statistics benchmark (JSON on stdout).

A stack of 2448×2048 Mono16 frames (12-bit data, generated on the fly from a small bank of distinct noisy
frames, so the stack never exists in memory) is reduced by `uwlab.experiments.emva_stream.StackAccumulator`:
mean, temporal variance from frame pairs, spatial variance of the mean image, saturated fraction.
Reports processing throughput (MB/s of frame data, generation excluded) and peak memory: the tracemalloc
peak of the accumulator (in frames: bounded by a few frames whatever the stack length) and the process's
maximum resident set size.

Usage: python benchmarks/bench_emva.py [--frames N]
"""
from __future__ import annotations

import argparse
import json
import resource
import time
import tracemalloc

import numpy as np

from uwlab.experiments.emva.stream import StackAccumulator

WIDTH, HEIGHT = 2448, 2048
BANK = 3


def frame_bank(rng: np.random.Generator) -> list[np.ndarray]:
    base = 1000.0 + 20.0 * rng.standard_normal((HEIGHT, WIDTH), np.float32)
    return [np.clip(base + 30.0 * rng.standard_normal((HEIGHT, WIDTH), np.float32), 0, 4095).astype(np.uint16)
            for _ in range(BANK)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40, help="stack length (default 40)")
    args = parser.parse_args()
    bank = frame_bank(np.random.default_rng(0))
    frame_bytes = bank[0].nbytes
    tracemalloc.start()
    base_current, _ = tracemalloc.get_traced_memory()
    tracemalloc.reset_peak()
    acc = StackAccumulator(4095)
    busy = 0.0
    for i in range(args.frames):
        frame = bank[i % BANK]
        t0 = time.perf_counter()
        acc.add(frame)
        busy += time.perf_counter() - t0
    t0 = time.perf_counter()
    stats = acc.result()
    busy += time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    data_mb = args.frames * frame_bytes / 1e6
    print(json.dumps({
        "benchmark": "emva_stream", "frames": args.frames, "width": WIDTH, "height": HEIGHT, "pixel_format": "Mono16",
        "stack_mb": round(data_mb, 1), "seconds": round(busy, 3), "throughput_mb_s": round(data_mb / busy, 1),
        "peak_traced_mb": round((peak - base_current) / 1e6, 1),
        "peak_traced_frames": round((peak - base_current) / frame_bytes, 2),
        "max_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "temporal_var_dn2": round(stats.temporal_var_dn2, 3), "mean_dn": round(stats.mean_dn, 3),
    }))


if __name__ == "__main__":
    main()
