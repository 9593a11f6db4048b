"""Streaming EMVA 1288 statistics of a stack of frames, one frame at a time.

EMVA Standard 1288 Release 4.0 Linear (the General document uses the same definitions), for L frames y_l of M×N
pixels:

* mean μ_y over all frames and pixels (eq. 16, eq. 34);
* temporal variance σ²_y from frame pairs (eq. 18): half the mean square difference of the pair minus half the
  squared difference of the pair's means (the Release 4 correction for noise common to all pixels), averaged over
  the pairs (y_0, y_1), (y_2, y_3), … (an odd last frame enters the means only); μ[0] − μ[1] of the first pair is
  kept for the stability graph (§6.6, Fig. 6);
* temporal variance of the stack σ²_y.stack (eq. 65): the mean over the pixels of each pixel's variance over the
  L frames (divisor L − 1);
* spatial variance of the mean image ⟨y⟩ (eq. 33–35) without highpass (``spatial_var_dn2``, s²_y.measured over all
  the ROI) and, on the highpassed mean image (§8.1), corrected and split into row, column and pixel parts
  (eq. 36–44, `uwlab.experiments.frames.nonuniformity.spatial_variances`) with σ²_y (L = 2) or σ²_y.stack (L > 2);
* the fraction of pixels at or above the camera's clip level in any frame (`uwlab.experiments.saturation`);
* for a raw Bayer mosaic (``bayer``), the same statistics of each colour channel over its own sites
  (`uwlab.experiments.frames.frame.channel_pixels`; ``G`` pools both green sites), at the one clip level of the
  frame: EMVA 1288 Release 4.0 Linear §1.2 treats each colour channel of a colour camera as its own sensor. Each
  site of the 2 × 2 cell is a regular grid, an image of half the width and height: red and blue are each one such
  plane, with the highpassed split like a monochrome image's; green has two planes, and its split is the mean of
  theirs (each of its parts a variance over the sites of one plane: the offset between the two green sites is not
  in it, its total spatial variance ``spatial_var_dn2`` over both sites has it).

Memory is bounded by a few frames whatever L is: a uint32 sum image (exact for up to 32 768 frames of
16-bit data), a boolean "saturated in any frame" map and the first frame of the current pair; sums of squares of integer
deviations from an integer centre are accumulated exactly (integers, over row chunks of at most `CHUNK_PIXELS`), so
temporaries stay small and no precision is lost to cancellation. The highpass at the end works on a float32 copy
of ⟨y⟩ − μ_y.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, fields, replace

import numpy as np

from uwlab.errors import ConfigError
from uwlab.drivers.camera.pixels import bayer_sites
from uwlab.experiments.frames.frame import channel_pixels
from uwlab.experiments.frames.nonuniformity import HIGHPASS_MARGIN, SpatialVariances, highpass, spatial_variances

CHUNK_PIXELS = 1 << 16


@dataclass(frozen=True)
class StackStatistics:
    """EMVA statistics of one stack [DN, DN²]. ``spatial``: the highpassed, corrected spatial variances (None
    for a ROI too small for the highpass); ``mean_image``: ⟨y⟩ (float32) when requested; ``channels``: the
    statistics of each colour channel (``{"R", "G", "B"}``) of a Bayer stack, else None."""

    frames: int
    mean_dn: float
    temporal_var_dn2: float
    stack_var_dn2: float
    spatial_var_dn2: float
    spatial: SpatialVariances | None
    mean_diff_dn: float
    saturated_fraction: float
    mean_image: np.ndarray | None = None
    channels: dict[str, StackStatistics] | None = None
    pixels: int | None = None  # pixels per frame


class StackAccumulator:
    """Accumulates frames (2-D integer arrays of one shape) for `StackStatistics`; ``clip_dn`` is the camera's
    clip level (`uwlab.experiments.saturation.ClipLevel.dn`); ``keep_mean_image`` keeps ⟨y⟩ in the result (for
    the spectrograms, profiles and histograms of a nonuniformity stack); ``bayer``: the colour filter layout of a
    raw Bayer stack (its frames cropped from the mosaic at ``origin`` = (x0, y0): an odd offset shifts the phase),
    whose channels are accumulated too (``StackStatistics.channels``, the same rules over each channel's sites)."""

    def __init__(
        self, clip_dn: float, keep_mean_image: bool = False, bayer: str | None = None, origin: tuple[int, int] = (0, 0)
    ):
        self.clip_dn = float(clip_dn)
        self.keep_mean_image = keep_mean_image
        self.bayer = bayer
        self.origin = origin
        # each colour's site planes (frame[row::2, col::2]); a colour of two sites (green) is also pooled
        self._sites = bayer_sites(bayer, *origin) if bayer is not None else {}
        self._planes = {site: StackAccumulator(clip_dn) for cells in self._sites.values() for site in cells}
        self._pooled = {colour: StackAccumulator(clip_dn) for colour, cells in self._sites.items() if len(cells) > 1}
        self._sum: np.ndarray | None = None
        self._saturated: np.ndarray | None = None
        self._pending: np.ndarray | None = None
        self._centre = 0
        self._squares = 0
        self._pair_var_sum = 0.0
        self._pairs = 0
        self._mean_diff = 0.0
        self._first_diff_squares = 0
        self.frames = 0

    def add(self, frame: np.ndarray) -> None:
        frame = np.asarray(frame)
        if frame.ndim != 2 or frame.dtype.kind not in "ui":
            raise ConfigError("frame", f"{frame.dtype}{frame.shape}", "expected a 2-D integer image")
        if self._sum is None:
            self._sum = np.zeros(frame.shape, np.uint32)
            self._saturated = np.zeros(frame.shape, bool)
            self._centre = int(round(float(frame.mean())))
        elif frame.shape != self._sum.shape:
            raise ConfigError("frame", frame.shape, f"shape differs from the first frame {self._sum.shape}")
        for (row, col), plane in self._planes.items():
            plane.add(frame[row::2, col::2])
        if self._pooled:
            for colour, values in channel_pixels(frame, self.bayer, *self.origin).items():
                if colour in self._pooled:
                    self._pooled[colour].add(values[None, :])  # one row: both sites are not a rectangle
        if self.frames == 2:  # a third frame: the first pair's Σ (y − c)² now, from its sum (`_pair_squares`)
            self._squares = self._pair_squares(_centred_square_sum(self._sum, 2 * self._centre))
        np.add(self._sum, frame, out=self._sum, casting="unsafe")
        self._saturated |= frame >= self.clip_dn
        if self.frames >= 2:
            self._squares += _centred_square_sum(frame, self._centre)
        if self._pending is None:
            self._pending = frame.copy()
        else:
            diff_squares, diff_sum = _pair_sums(self._pending, frame)
            mean_diff = diff_sum / frame.size
            self._pair_var_sum += 0.5 * (diff_squares / frame.size - mean_diff**2)  # eq. 18
            if self._pairs == 0:
                self._mean_diff = mean_diff
                self._first_diff_squares = diff_squares
            self._pairs += 1
            self._pending = None
        self.frames += 1

    def _pair_squares(self, sum_squares: int) -> int:
        """Σ_l Σ (y_l − c)² of the first two frames from Σ (y_0 + y_1 − 2c)² and the pair's Σ (y_0 − y_1)²: per
        pixel (a − c)² + (b − c)² = ((a + b − 2c)² + (a − b)²) / 2, exactly (the numerator is even). A two-frame
        stack (every photon-transfer point) so needs no pass of squares over its frames."""
        return (sum_squares + self._first_diff_squares) // 2

    def result(self) -> StackStatistics:
        if self._pairs == 0:
            raise ConfigError("frames", self.frames, "need at least 2 frames for the temporal variance")
        n, frames = self._sum.size, self.frames
        sum_total = int(self._sum.sum(dtype=np.uint64))
        mean = sum_total / (n * frames)
        # with D = Σ_l y_l − L c per pixel (c the integer centre): eq. 65 is (Σ_l Σ (y − c)² − Σ D² / L) / ((L − 1) MN)
        # and eq. 35 of the unfiltered mean image is (Σ D² − (Σ D)² / MN) / (L² MN)
        d_sum = sum_total - n * frames * self._centre
        d_squares = _centred_square_sum(self._sum, frames * self._centre)
        squares = self._pair_squares(d_squares) if frames == 2 else self._squares
        stack_var = (squares - d_squares / frames) / ((frames - 1) * n)
        measured = (d_squares - d_sum * d_sum / n) / (frames**2 * n)
        temporal = self._pair_var_sum / self._pairs
        deviation = self._deviation_image(mean)
        spatial = None
        if min(deviation.shape) > 2 * HIGHPASS_MARGIN + 1:
            spatial = spatial_variances(highpass(deviation), stack_var if frames > 2 else temporal, frames)
        return StackStatistics(
            frames=frames,
            mean_dn=mean,
            temporal_var_dn2=temporal,
            stack_var_dn2=stack_var,
            spatial_var_dn2=measured,
            spatial=spatial,
            mean_diff_dn=self._mean_diff,
            saturated_fraction=float(np.count_nonzero(self._saturated)) / n,
            mean_image=np.add(deviation, np.float32(mean), out=deviation) if self.keep_mean_image else None,
            pixels=n,
            channels=self._channel_results() if self._sites else None,
        )

    def _channel_results(self) -> dict[str, StackStatistics]:
        """Each colour's statistics: its one plane's, or (green) its pooled sites' with the mean of its planes'
        highpassed splits."""
        out = {}
        for colour, cells in self._sites.items():
            planes = [self._planes[site].result() for site in cells]
            if colour not in self._pooled:
                out[colour] = planes[0]
                continue
            splits = [plane.spatial for plane in planes]
            split = None if any(s is None for s in splits) else _mean_split([s for s in splits if s is not None])
            out[colour] = replace(self._pooled[colour].result(), spatial=split)
        return out

    def _deviation_image(self, mean: float) -> np.ndarray:
        """⟨y⟩ − μ_y as float32 (computed from the exact integer sum, in row chunks)."""
        out = np.empty(self._sum.shape, np.float32)
        scale = 1.0 / self.frames
        for rows, target in zip(_row_chunks(self._sum), _row_chunks(out), strict=True):
            np.subtract(rows * scale, mean, out=target, casting="unsafe")
        return out


def _mean_split(splits: list[SpatialVariances]) -> SpatialVariances:
    """The mean of the splits of equally weighted planes (the smallest plane's rows and columns)."""
    mean = {f.name: float(np.mean([getattr(s, f.name) for s in splits])) for f in fields(SpatialVariances)}
    return SpatialVariances(**mean | {"rows": min(s.rows for s in splits), "cols": min(s.cols for s in splits)})


def _row_chunks(image: np.ndarray) -> list[np.ndarray]:
    """Views of at most `CHUNK_PIXELS` pixels and an eighth of the image each (whole rows), so temporaries stay a
    small fraction of a frame."""
    rows = max(1, min(CHUNK_PIXELS, image.size // 8) // image.shape[1])
    return [image[i : i + rows] for i in range(0, image.shape[0], rows)]


def _centred_square_sum(image: np.ndarray, centre: int) -> int:
    """Σ (y − c)² over an integer image, exactly: int64 dot products over row blocks small enough not to overflow,
    summed as a Python int."""
    bound = max(abs(int(image.max()) - centre), abs(int(image.min()) - centre), 1)
    rows = max(1, min(CHUNK_PIXELS, image.size // 8, (1 << 62) // (bound * bound)) // image.shape[1])
    total = 0
    for start in range(0, image.shape[0], rows):
        d = image[start : start + rows].astype(np.int64).ravel()
        d -= centre
        total += int(d @ d)
    return total


def _pair_sums(a: np.ndarray, b: np.ndarray) -> tuple[int, int]:
    """(Σ (a − b)², Σ (a − b)) of two integer frames, exactly, accumulated in row chunks."""
    total, squares = 0, 0
    for rows_a, rows_b in zip(_row_chunks(a), _row_chunks(b), strict=True):
        diff = np.subtract(rows_a, rows_b, dtype=np.int64).ravel()
        total += int(diff.sum())
        squares += int(diff @ diff)
    return squares, total


def stack_statistics(
    frames: Iterable[np.ndarray],
    clip_dn: float,
    keep_mean_image: bool = False,
    bayer: str | None = None,
    origin: tuple[int, int] = (0, 0),
) -> StackStatistics:
    """`StackStatistics` of an iterable of frames, consumed one at a time (a generator keeps memory flat); with
    ``bayer``, per colour channel too (`StackAccumulator`)."""
    acc = StackAccumulator(clip_dn, keep_mean_image, bayer, origin)
    for frame in frames:
        acc.add(frame)
    return acc.result()
