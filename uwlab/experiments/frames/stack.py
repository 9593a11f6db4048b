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

Memory is bounded by a few frames whatever L is: the first pair and the frame waiting for its partner, the first
pair's sum, for L > 2 a uint32 sum image (exact for up to 32 768 frames of 16-bit data) and, once a frame reaches
the clip level, a boolean "saturated in any frame" map. Every sum is an exact integer, so no precision is lost to
cancellation: each frame's Σ y, each pair's Σ (y_0 − y_1)² and Σ (y_0 + y_1)² (so Σ y_0² + Σ y_1², one pass over
the pair's uint16 sum instead of two over its frames), an odd last frame's Σ y²; 8- and 16-bit frames through
OpenCV: sums of squares below 2^49 from its squared L2 norm, rounded (`_norm_squares`), other sums over pieces of the
image small enough that every partial sum stays below 2^31, where any accumulator is exact (`_pieces`); other types
in int64. The sums about an integer centre c follow (`StackAccumulator.result`). For
the highpass, Σ_l y_l − L c is filtered once, as int16 when its values allow (a pair of 12-bit frames) else as
float32, both exact integers, and its statistics are scaled by 1/L
(`uwlab.experiments.frames.nonuniformity.highpassed_variances`); only a kept mean image takes the float32 ⟨y⟩ − μ_y
route. A thread that runs many stacks (a descriptor's photon-transfer points) reuses its work images
(`WorkImages`): fresh 10–20 MB arrays at every point would each cost their page faults.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, fields, replace

import numpy as np

from uwlab.errors import ConfigError
from uwlab.drivers.camera.pixels import bayer_sites
from uwlab.experiments.frames.frame import channel_pixels
from uwlab.experiments.frames.nonuniformity import (
    HIGHPASS_MARGIN,
    SpatialVariances,
    highpass,
    highpassed_variances,
    spatial_variances,
)

CHUNK_PIXELS = 1 << 16
PIECE_WIDTH = 1 << 11  # columns of the pieces OpenCV sums exactly (`_pieces`)
EXACT_PARTIAL = 1 << 31  # any integer accumulator (and double) adds integers below this exactly
FLOAT32_EXACT = 1 << 24  # integers of magnitude below this are exact in float32
NORM_EXACT = 1 << 49  # OpenCV's squared L2 norms below this round to the exact integer (`_norm_squares`)
_OPENCV_SUMS = (np.dtype(np.uint8), np.dtype(np.uint16))


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


class WorkImages:
    """Work images (a frame read, the kept pair and its sum, the highpass's input and output) that one thread
    reuses from one stack to the next: fresh 10–20 MB arrays at every photon-transfer point of a lab-size descriptor
    cost their page faults each time (about 2 ms of CPU per frame). One per thread, for one stack at a time: an
    accumulator's kept frames live in them until its result."""

    def __init__(self) -> None:
        self._images: dict[str, np.ndarray] = {}

    def get(self, name: str, shape: tuple[int, ...], dtype: type = np.float32) -> np.ndarray:
        image = self._images.get(name)
        if image is None or image.shape != shape or image.dtype != dtype:
            image = self._images[name] = np.empty(shape, dtype)
        return image


class StackAccumulator:
    """Accumulates frames (2-D integer arrays of one shape) for `StackStatistics`; ``clip_dn`` is the camera's
    clip level (`uwlab.experiments.saturation.ClipLevel.dn`); ``keep_mean_image`` keeps ⟨y⟩ in the result (for
    the spectrograms, profiles and histograms of a nonuniformity stack); ``bayer``: the colour filter layout of a
    raw Bayer stack (its frames cropped from the mosaic at ``origin`` = (x0, y0): an odd offset shifts the phase),
    whose channels are accumulated too (``StackStatistics.channels``, the same rules over each channel's sites);
    ``work``: the calling thread's `WorkImages` to reuse (else fresh arrays); ``stable_frames``: the caller leaves
    each frame it adds unchanged until the next frame has been added (the last one until `result`), as a reader
    alternating two buffers does, so that a frame waiting for its partner is not copied (else every frame may be
    overwritten once `add` returns)."""

    def __init__(
        self,
        clip_dn: float,
        keep_mean_image: bool = False,
        bayer: str | None = None,
        origin: tuple[int, int] = (0, 0),
        work: WorkImages | None = None,
        stable_frames: bool = False,
    ):
        self.work = work
        self.stable_frames = stable_frames
        self.clip_dn = float(clip_dn)
        self.keep_mean_image = keep_mean_image
        self.bayer = bayer
        self.origin = origin
        # each colour's site planes (frame[row::2, col::2]); a colour of two sites (green) is also pooled
        self._sites = bayer_sites(bayer, *origin) if bayer is not None else {}
        self._planes = {site: StackAccumulator(clip_dn) for cells in self._sites.values() for site in cells}
        self._pooled = {colour: StackAccumulator(clip_dn) for colour, cells in self._sites.items() if len(cells) > 1}
        self._shape: tuple[int, ...] = ()  # set by the first frame
        # the first pair (kept only without its uint16 sum) or that sum, kept until a second pair makes the sum image
        self._first_pair: tuple[np.ndarray, np.ndarray] | None = None
        self._first_pair_sum: np.ndarray | None = None
        self._sum: np.ndarray | None = None  # uint32 Σ_l y_l of the pairs, from the second pair on
        self._saturated: np.ndarray | None = None  # allocated at the first frame reaching the clip level
        self._pending: np.ndarray | None = None
        self._pending_sum = 0
        self._pending_bound = 0
        self._bound = 0  # the largest |y| of any frame
        self._centre = 0
        self._total = 0  # Σ_l Σ y_l
        self._squares = 0  # Σ_l Σ (y_l − c)²
        self._pair_var_sum = 0.0
        self._pairs = 0
        self._mean_diff = 0.0
        self._first_diff_squares = 0
        self.frames = 0

    def add(self, frame: np.ndarray, top: int | None = None) -> None:
        """Adds ``frame``; ``top``: its largest value, when the caller has it (a reader that checked the frame's
        range), which saves a pass over it."""
        frame = np.asarray(frame)
        if frame.ndim != 2 or frame.dtype.kind not in "ui":
            raise ConfigError("frame", f"{frame.dtype}{frame.shape}", "expected a 2-D integer image")
        if not self._shape:
            self._shape = frame.shape
        elif frame.shape != self._shape:
            raise ConfigError("frame", frame.shape, f"shape differs from the first frame {self._shape}")
        for (row, col), plane in self._planes.items():
            plane.add(frame[row::2, col::2])
        if self._pooled and self.bayer is not None:
            for colour, values in channel_pixels(frame, self.bayer, *self.origin).items():
                if colour in self._pooled:
                    self._pooled[colour].add(values[None, :])  # one row: both sites are not a rectangle
        top = int(frame.max()) if top is None else top
        bound = max(abs(top), abs(int(frame.min())) if frame.dtype.kind == "i" else 0)
        self._bound = max(self._bound, bound)
        total = _total(frame, bound)
        n = frame.size
        if self.frames == 0:
            self._centre = round(total / n)  # an integer near the mean: any is exact, a near one keeps sums small
        c = self._centre
        self._total += total
        if top >= self.clip_dn:  # y ≥ clip ⟺ y ≥ ⌈clip⌉ for integers: compared in the frame's own type
            if self._saturated is None:
                self._saturated = np.zeros(frame.shape, bool)
            threshold = max(math.ceil(self.clip_dn), int(np.iinfo(frame.dtype).min))
            self._saturated |= frame >= frame.dtype.type(threshold)
        if self._pending is None:
            self._pending = (
                frame if self.stable_frames else self._keep(frame, "first" if self.frames == 0 else "pending")
            )
            self._pending_sum, self._pending_bound = total, bound
        else:
            first, pair_bound = self._pending, max(self._pending_bound, bound)
            diff_squares = _diff_square_sum(first, frame, pair_bound)
            pair_total = self._pending_sum + total
            pair_squares, pair_sum = self._pair_square_sum(first, frame, pair_bound, diff_squares)
            self._squares += pair_squares - 2 * c * pair_total + 2 * n * c * c  # Σ (y − c)² of both
            diff_sum = self._pending_sum - total
            mean_diff = diff_sum / n
            self._pair_var_sum += 0.5 * (diff_squares / n - mean_diff**2)  # eq. 18
            if self._pairs == 0:
                self._mean_diff = mean_diff
                self._first_diff_squares = diff_squares
                self._first_pair_sum = pair_sum
                if pair_sum is None:
                    kept = self._keep(first, "first") if self.stable_frames else first
                    self._first_pair = (kept, self._keep(frame, "second"))
            else:
                self._add_pair(first, frame, pair_sum)
            self._pairs += 1
            self._pending = None
        self.frames += 1

    def _add_pair(self, a: np.ndarray, b: np.ndarray, pair_sum: np.ndarray | None) -> None:
        """Adds a pair after the first to the uint32 sum image (made from the first pair at the second), by its sum
        when it has one: one pass over the sum image per pair."""
        if self._sum is None:
            self._sum = self._first_sum()
            self._first_pair = self._first_pair_sum = None
        for addend in (a, b) if pair_sum is None else (pair_sum,):
            np.add(self._sum, addend, out=self._sum, casting="unsafe")

    def result(self) -> StackStatistics:
        if self._pairs == 0:
            raise ConfigError("frames", self.frames, "need at least 2 frames for the temporal variance")
        frames, c = self.frames, self._centre
        n = self._shape[0] * self._shape[1]
        sum_total = self._total
        mean = sum_total / (n * frames)
        # with D = Σ_l y_l − L c per pixel (c the integer centre): eq. 65 is (Σ_l Σ (y − c)² − Σ D² / L) / ((L − 1) MN)
        # and eq. 35 of the unfiltered mean image is (Σ D² − (Σ D)² / MN) / (L² MN); for L = 2, per pixel
        # (a + b − 2c)² = 2 (a − c)² + 2 (b − c)² − (a − b)², so Σ D² needs no pass over the frames
        d_sum = sum_total - n * frames * c
        squares = self._squares
        if self._pending is not None:  # an odd last frame, in no pair
            squares += _square_sum(self._pending, self._pending_bound) - 2 * c * self._pending_sum + n * c * c
        if frames == 2:
            d_squares = 2 * squares - self._first_diff_squares
        else:
            d_squares = _centred_square_sum(self._sum_image(), frames * c)
        stack_var = (squares - d_squares / frames) / ((frames - 1) * n)
        measured = (d_squares - d_sum * d_sum / n) / (frames**2 * n)
        temporal = self._pair_var_sum / self._pairs
        split_var = stack_var if frames > 2 else temporal
        spatial, mean_image = None, None
        big_enough = min(self._shape) > 2 * HIGHPASS_MARGIN + 1
        if self.keep_mean_image or frames * self._bound >= FLOAT32_EXACT:
            deviation = self._deviation_image(mean)
            if big_enough:
                spatial = spatial_variances(highpass(deviation), split_var, frames)
            if self.keep_mean_image:
                mean_image = np.add(deviation, np.float32(mean), out=deviation)
        elif big_enough:
            smooth = self._work("smooth", np.float32)
            spatial = highpassed_variances(self._offset_sum(frames * c), split_var, frames, 1.0 / frames, smooth)
        saturated = 0 if self._saturated is None else np.count_nonzero(self._saturated)
        return StackStatistics(
            frames=frames,
            mean_dn=mean,
            temporal_var_dn2=temporal,
            stack_var_dn2=stack_var,
            spatial_var_dn2=measured,
            spatial=spatial,
            mean_diff_dn=self._mean_diff,
            saturated_fraction=float(saturated) / n,
            mean_image=mean_image,
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

    def _sum_image(self) -> np.ndarray:
        """Σ_l y_l (uint32): the sum image of the pairs, or the first pair's sum, with an odd last frame added in a
        new array (the accumulator stays as it was)."""
        if self._sum is not None:
            total = self._sum
        else:
            total = self._first_sum()
        if self._pending is not None:
            total = np.add(total, self._pending, dtype=np.uint32, casting="unsafe")
        return total

    def _first_sum(self) -> np.ndarray:
        """The first pair's sum as a new uint32 image (from its uint16 sum, else from its kept frames)."""
        if self._first_pair_sum is not None:
            return self._first_pair_sum.astype(np.uint32)
        assert self._first_pair is not None  # kept by the first pair without its sum
        return np.add(*self._first_pair, dtype=np.uint32, casting="unsafe")

    def _offset_sum(self, offset: int) -> np.ndarray:
        """Σ_l y_l − ``offset``, exactly: int16 for a pair of unsigned frames whose values allow it (added in
        uint16, the offset taken modulo 2^16: the int16 view is exact when every value lies in −2^15 … 2^15 − 1;
        OpenCV filters int16 faster than float32 and needs no conversion), else float32 (every value an integer
        below 2^24)."""
        pair_sum, top = self._first_pair_sum, 2 * self._bound
        if self.frames == 2 and pair_sum is not None and offset <= 1 << 15 and top - offset < 1 << 15:
            out = self._work("offset sum", np.uint16)
            return np.subtract(pair_sum, np.uint16(offset), out=out).view(np.int16)
        out = self._work("sum", np.float32)
        np.copyto(out, self._sum_image(), casting="unsafe")
        return np.subtract(out, np.float32(offset), out=out)

    def _pair_square_sum(
        self, a: np.ndarray, b: np.ndarray, bound: int, diff_squares: int
    ) -> tuple[int, np.ndarray | None]:
        """(Σ a² + Σ b², a + b) of a pair, exactly: per pixel a² + b² = ((a + b)² + (a − b)²) / 2, so with
        Σ (a − b)² known one pass over the pair's sum (uint16 when it fits, else None; the first pair's highpass
        and the sum image use it) replaces two over the frames."""
        if not (a.dtype in _OPENCV_SUMS and b.dtype in _OPENCV_SUMS and 2 * bound < 1 << 16):
            return _square_sum(a, bound) + _square_sum(b, bound), None
        name = "first pair sum" if self._pairs == 0 else "pair sum"
        pair_sum = np.add(a, b, out=self._work(name, np.uint16), dtype=np.uint16)
        return (_square_sum(pair_sum, 2 * bound) + diff_squares) // 2, pair_sum

    def _keep(self, frame: np.ndarray, name: str) -> np.ndarray:
        """A copy of ``frame`` (the caller may reuse its buffer), in the work image ``name`` when reused."""
        if self.work is None:
            return frame.copy()
        kept = self.work.get(name, frame.shape, frame.dtype.type)
        np.copyto(kept, frame)
        return kept

    def _work(self, name: str, dtype: type) -> np.ndarray:
        """A work image of the frames' shape: the thread's reused one (`WorkImages`) or a fresh one."""
        return np.empty(self._shape, dtype) if self.work is None else self.work.get(name, self._shape, dtype)

    def _deviation_image(self, mean: float) -> np.ndarray:
        """⟨y⟩ − μ_y as float32 (computed from the exact integer sum, in row chunks)."""
        total = self._sum_image()
        out = np.empty(total.shape, np.float32)
        scale = 1.0 / self.frames
        for rows, target in zip(_row_chunks(total), _row_chunks(out), strict=True):
            np.subtract(rows * scale, mean, out=target, casting="unsafe")
        return out


FLOAT_FIELDS = tuple(f.name for f in fields(SpatialVariances) if f.name not in ("rows", "cols"))


def _mean_split(splits: list[SpatialVariances]) -> SpatialVariances:
    """The mean of the splits of equally weighted planes (the smallest plane's rows and columns)."""
    mean = {part: float(np.mean([getattr(s, part) for s in splits])) for part in FLOAT_FIELDS}
    return SpatialVariances(**mean, rows=min(s.rows for s in splits), cols=min(s.cols for s in splits))


def _row_chunks(image: np.ndarray) -> list[np.ndarray]:
    """Views of at most `CHUNK_PIXELS` pixels and an eighth of the image each (whole rows), so temporaries stay a
    small fraction of a frame."""
    rows = max(1, min(CHUNK_PIXELS, image.size // 8) // image.shape[1])
    return [image[i : i + rows] for i in range(0, image.shape[0], rows)]


def _pieces(image: np.ndarray, bound: int) -> tuple[list[np.ndarray], np.ndarray] | None:
    """The memory of a C-contiguous 8- or 16-bit ``image`` regrouped as pieces of `PIECE_WIDTH` columns and at most R
    rows, R · ``bound`` < 2^31 (``bound``: the largest term a column adds per row), so that every partial sum of
    OpenCV's column reductions stays below 2^31, exact in any accumulator; and the fewer than `PIECE_WIDTH` elements
    left over (1-D, summed in int64: a last piece of fewer rows takes the rest, which as a remainder of whole pieces
    could be most of a frame). None for other images (the int64 route)."""
    rows = EXACT_PARTIAL // max(bound, 1)
    if image.dtype not in _OPENCV_SUMS or not image.flags.c_contiguous or rows < 1:
        return None
    flat = image.reshape(-1)
    width = min(PIECE_WIDTH, flat.size)
    body = flat.size // width * width
    step = min(rows, body // width) * width
    return [flat[i : min(i + step, body)].reshape(-1, width) for i in range(0, body, step)], flat[body:]


def _total(image: np.ndarray, bound: int) -> int:
    """Σ y of an integer image with |y| ≤ ``bound``, exactly."""
    regrouped = _pieces(image, max(bound, 1) * PIECE_WIDTH)
    if regrouped is None:
        return int(image.sum(dtype=np.int64))
    import cv2

    pieces, rest = regrouped
    return sum(int(cv2.sumElems(piece)[0]) for piece in pieces) + int(rest.sum(dtype=np.int64))


def _norm_squares(a: np.ndarray, b: np.ndarray | None, bound: int) -> int | None:
    """Σ a² (or, given ``b``, Σ (a − b)²) of 8- or 16-bit unsigned images with values ≤ ``bound`` and contiguous
    rows, exactly, from OpenCV's squared L2 norm rounded to an integer, when the sum is certainly below `NORM_EXACT`;
    else None. OpenCV adds the squares in double, exact below 2^53; with Intel IPP (the PyPI wheels) it returns the
    square of IPP's norm, a square root squared: relative error within 3 · 2^-53, so under 0.2 below 2^49, and the
    rounded value is the exact integer. One pass over the image, no temporary (Σ (a − b)²: no |a − b| image)."""
    images = (a,) if b is None else (a, b)
    if any(x.dtype not in _OPENCV_SUMS or x.ndim != 2 or x.strides[1] != x.itemsize for x in images):
        return None
    if b is not None and (b.dtype != a.dtype or b.shape != a.shape):
        return None
    if a.size * bound * bound >= NORM_EXACT:
        return None
    import cv2

    return round(cv2.norm(a, cv2.NORM_L2SQR) if b is None else cv2.norm(a, b, cv2.NORM_L2SQR))


def _square_sum(image: np.ndarray, bound: int) -> int:
    """Σ y² of an integer image with |y| ≤ ``bound``, exactly: OpenCV's squared norm (`_norm_squares`), else its
    column sums of squares of each piece (`_pieces`; integers below 2^53 in double), or int64."""
    squares = _norm_squares(image, None, bound)
    if squares is not None:
        return squares
    regrouped = _pieces(image, bound * bound)
    if regrouped is None:
        return _centred_square_sum(image, 0)
    import cv2

    pieces, rest = regrouped
    columns = np.zeros(pieces[0].shape[1] if pieces else 0)
    for piece in pieces:
        columns += cv2.reduce(piece, 0, cv2.REDUCE_SUM2, dtype=cv2.CV_64F).ravel()
    left = rest.astype(np.int64)
    return int(columns.astype(np.int64).sum()) + int(left @ left)


def _sums(image: np.ndarray, bound: int) -> tuple[int, int]:
    """(Σ y, Σ y²) of an integer image with |y| ≤ ``bound``, exactly."""
    return _total(image, bound), _square_sum(image, bound)


def _diff_square_sum(a: np.ndarray, b: np.ndarray, bound: int) -> int:
    """Σ (a − b)² of two integer images with |values| ≤ ``bound``, exactly (|a − b| of unsigned images is exact in
    their own type)."""
    squares = _norm_squares(a, b, bound)
    if squares is not None:
        return squares
    if a.dtype == b.dtype and a.dtype in _OPENCV_SUMS:
        import cv2

        return _square_sum(cv2.absdiff(a, b), bound)
    squares = 0
    for rows_a, rows_b in zip(_row_chunks(a), _row_chunks(b), strict=True):
        diff = np.subtract(rows_a, rows_b, dtype=np.int64).ravel()
        squares += int(diff @ diff)
    return squares


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


def stack_statistics(
    frames: Iterable[np.ndarray],
    clip_dn: float,
    keep_mean_image: bool = False,
    bayer: str | None = None,
    origin: tuple[int, int] = (0, 0),
    work: WorkImages | None = None,
    stable_frames: bool = False,
) -> StackStatistics:
    """`StackStatistics` of an iterable of frames, consumed one at a time (a generator keeps memory flat); with
    ``bayer``, per colour channel too (`StackAccumulator`)."""
    acc = StackAccumulator(clip_dn, keep_mean_image, bayer, origin, work, stable_frames)
    for frame in frames:
        acc.add(frame)
    return acc.result()
