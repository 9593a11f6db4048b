"""Streaming EMVA 1288 statistics of a stack of frames, one frame at a time.

EMVA 1288 Release 4.0 (linear), computation of mean and variance: for L frames y_l of M×N pixels

* mean μ_y = (1/(L M N)) Σ_l Σ_mn y_l[m, n];
* temporal variance from frame pairs, σ²_y = (1/2) var(y_A − y_B) with the mean difference removed,
  averaged over the pairs (y_1, y_2), (y_3, y_4), … (an odd last frame enters the mean only);
* spatial variance s²_y,measured of the L-frame mean image (unbiased, ddof = 1), not yet corrected for the
  residual temporal noise σ²_y / L (the caller does that).

Memory is bounded by a few frames whatever L is: a uint32 sum image (exact for up to 65 536 frames of
16-bit data), a boolean "saturated in any frame" map and the first frame of the current pair; the
variances are accumulated over row chunks (`CHUNK_PIXELS`), so temporaries stay small.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from uwlab.errors import ConfigError

CHUNK_PIXELS = 1 << 18


@dataclass(frozen=True)
class StackStatistics:
    """EMVA statistics of one stack (DN, DN²); ``saturated_fraction``: pixels at or above the clip level in any
    frame (`uwlab.experiments.saturation`)."""

    frames: int
    mean_dn: float
    temporal_var_dn2: float
    spatial_var_dn2: float
    saturated_fraction: float


class StackAccumulator:
    """Accumulates frames (2-D integer arrays of one shape) for `StackStatistics`; ``clip_dn`` is the camera's
    clip level (`uwlab.experiments.saturation.ClipLevel.dn`)."""

    def __init__(self, clip_dn: float):
        self.clip_dn = float(clip_dn)
        self._sum: np.ndarray | None = None
        self._saturated: np.ndarray | None = None
        self._pending: np.ndarray | None = None
        self._pair_var_sum = 0.0
        self._pairs = 0
        self.frames = 0

    def add(self, frame: np.ndarray) -> None:
        frame = np.asarray(frame)
        if frame.ndim != 2 or frame.dtype.kind not in "ui":
            raise ConfigError("frame", f"{frame.dtype}{frame.shape}", "expected a 2-D integer image")
        if self._sum is None:
            self._sum = np.zeros(frame.shape, np.uint32)
            self._saturated = np.zeros(frame.shape, bool)
        elif frame.shape != self._sum.shape:
            raise ConfigError("frame", frame.shape, f"shape differs from the first frame {self._sum.shape}")
        np.add(self._sum, frame, out=self._sum, casting="unsafe")
        self._saturated |= frame >= self.clip_dn
        if self._pending is None:
            self._pending = frame.copy()
        else:
            self._pair_var_sum += 0.5 * _difference_variance(self._pending, frame)
            self._pairs += 1
            self._pending = None
        self.frames += 1

    def result(self) -> StackStatistics:
        if self._pairs == 0:
            raise ConfigError("frames", self.frames, "need at least 2 frames for the temporal variance")
        n = self._sum.size
        total_mean = float(self._sum.sum(dtype=np.uint64)) / n
        squares = sum(_centred_squares(rows, total_mean) for rows in _row_chunks(self._sum))
        return StackStatistics(
            frames=self.frames, mean_dn=total_mean / self.frames,
            temporal_var_dn2=self._pair_var_sum / self._pairs,
            spatial_var_dn2=squares / (n - 1) / self.frames**2,
            saturated_fraction=float(np.count_nonzero(self._saturated)) / n,
        )


def _row_chunks(image: np.ndarray) -> list[np.ndarray]:
    """Views of about `CHUNK_PIXELS` pixels each, so temporaries stay a small fraction of a frame."""
    rows = max(1, CHUNK_PIXELS // image.shape[1])
    return [image[i : i + rows] for i in range(0, image.shape[0], rows)]


def _centred_squares(block: np.ndarray, centre: float) -> float:
    d = block.astype(np.float64).ravel() - centre
    return float(d @ d)


def _difference_variance(a: np.ndarray, b: np.ndarray) -> float:
    """var(a − b) over all pixels (population variance, mean difference removed), in row chunks."""
    total, squares = 0, 0.0
    for rows_a, rows_b in zip(_row_chunks(a), _row_chunks(b)):
        diff = np.subtract(rows_a, rows_b, dtype=np.int64).ravel()
        total += int(diff.sum())
        squares += float(diff @ diff)
    n = a.size
    return (squares - total * total / n) / n


def stack_statistics(frames: Iterable[np.ndarray], clip_dn: float) -> StackStatistics:
    """`StackStatistics` of an iterable of frames, consumed one at a time (a generator keeps memory flat)."""
    acc = StackAccumulator(clip_dn)
    for frame in frames:
        acc.add(frame)
    return acc.result()
