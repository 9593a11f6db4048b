"""EMVA 1288 Release 4.0 spatial nonuniformity of mean images: the highpass filter, spatial variances and their
split into row, column and pixel parts, DSNU and PRNU, spectrograms, profiles and defect-pixel histograms.

Conventions (EMVA Standard 1288 Release 4.0 Linear; the General document repeats them in its §4 and §8): an image
has M rows (index m) and N columns (index n); ⟨y⟩ is the mean of L frames (eq. 33); values in DN.

* Highpass (§8.1): the image smoothed by a 7×7 box, then an 11×11 box, then a 3×3 binomial filter, is subtracted
  from it. The three separable filters make one 19-tap kernel per axis; the result is kept only where the kernel
  lies inside the image (`HIGHPASS_MARGIN` = 9 pixels are dropped on every side: no border rule is assumed);
  OpenCV's separable filter applies it.
  For white noise the filter keeps `white_noise_gain()` = 0.9885 of the variance (−0.6 % in a standard
  deviation), for a pattern constant along rows or columns `line_noise_gain()` = 0.8891 (−5.7 %): these are the
  standard's definitions, not corrected here. Every statistic below is computed on highpassed images except the
  profiles (§8.7).
* Spatial variance (§4.2): s²_y.measured = (1/MN) Σ (⟨y⟩ − μ_y)² (eq. 35), corrected for the residual temporal
  variance, s²_y = s²_y.measured − σ²_y / L (eq. 36);
* row, column and pixel parts (§4.3): from the variances of the mean row and the mean column, corrected for their
  residual temporal variance, s²_y.cav and s²_y.rav (eq. 41), the exact solution eq. 44 of the system eq. 42;
* DSNU₁₂₈₈ = s_y.dark / K [e⁻] (eq. 66), PRNU₁₂₈₈ = √(s²_y.50 − s²_y.dark) / (μ_y.50 − μ_y.dark) [%] (eq. 67), for
  the total and for each part (§8.3); None where the radicand is negative;
* spectrograms (§8.6): P[v] = (1/M) Σ_m |ŷ[m][v]|², ŷ the DFT of each mean-free row scaled by 1/√N (eq. 70–71),
  shown as √P[v] against v/N up to the Nyquist frequency (vertical: columns instead of rows);
* profiles (§8.7): middle row M//2 (column N//2), mean, maximum and minimum over all rows (columns), unfiltered;
* logarithmic histogram (§8.8, eq. 73–76) with Q ≤ 256 bins of width I/L and the normal density of the image's
  own standard deviation s_nw as the model (the standard's "non-white" s_nw, taken here as the standard deviation
  of the histogrammed image); accumulated histogram of |y − μ_y| (eq. 77–81), in percent of the pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

HIGHPASS_BOXES = (7, 11)
HIGHPASS_BINOMIAL = np.array([0.25, 0.5, 0.25])
HIGHPASS_MARGIN = 9
HISTOGRAM_MAX_BINS = 256


def smoothing_kernel() -> np.ndarray:
    """The 19-tap 1-D kernel of the §8.1 smoothing: box 7 ∗ box 11 ∗ binomial [1, 2, 1]/4 (sums to 1)."""
    kernel = np.convolve(np.ones(HIGHPASS_BOXES[0]) / HIGHPASS_BOXES[0], np.ones(HIGHPASS_BOXES[1]) / HIGHPASS_BOXES[1])
    return np.convolve(kernel, HIGHPASS_BINOMIAL)


def white_noise_gain() -> float:
    """Fraction of a white (pixel) pattern's variance that the highpass keeps: Σ (δ − h⊗h)²."""
    h = smoothing_kernel()
    centre = len(h) // 2
    return float(1.0 - 2.0 * h[centre] ** 2 + np.sum(h**2) ** 2)


def line_noise_gain() -> float:
    """Fraction of a white row (or column) pattern's variance that the highpass keeps: Σ (δ − h)²."""
    h = smoothing_kernel()
    return float(1.0 - 2.0 * h[len(h) // 2] + np.sum(h**2))


def highpass(image: np.ndarray) -> np.ndarray:
    """The §8.1 highpass of ``image`` (float32 result, `HIGHPASS_MARGIN` pixels smaller on every side).

    >>> highpass(np.full((40, 30), 7.0)).shape
    (22, 12)
    """
    import cv2

    image = np.asarray(image, np.float32)
    m = HIGHPASS_MARGIN
    if min(image.shape) <= 2 * m + 1:
        raise ValueError(f"image {image.shape} too small for the EMVA 1288 highpass (needs > {2 * m + 1} px a side)")
    kernel = smoothing_kernel().astype(np.float32)
    smooth = cv2.sepFilter2D(image, cv2.CV_32F, kernel, kernel, borderType=cv2.BORDER_REFLECT)
    inner = (slice(m, -m), slice(m, -m))
    return np.subtract(image[inner], smooth[inner], out=smooth[inner])


@dataclass(frozen=True)
class SpatialVariances:
    """Spatial variances of one (highpassed) mean image [DN²] (§4.2–4.3): ``measured`` eq. 35, ``total`` eq. 36,
    ``cav``/``rav`` eq. 41 and the ``row``, ``col``, ``pixel`` parts of eq. 44 (row + col + pixel = total)."""

    measured: float
    total: float
    cav: float
    rav: float
    row: float
    col: float
    pixel: float
    rows: int
    cols: int

    @property
    def parts(self) -> dict[str, float]:
        return {"total": self.total, "row": self.row, "col": self.col, "pixel": self.pixel}


def spatial_variances(mean_image: np.ndarray, temporal_var_dn2: float, frames: int) -> SpatialVariances:
    """The variances of a mean image of ``frames`` frames with temporal variance σ²_y (eq. 35–44).

    A pure column pattern of variance s² (constant down each column) has s²_y.col = s² exactly:

    >>> img = np.tile(np.array([1.0, -1.0] * 8), (12, 1))
    >>> round(spatial_variances(img, 0.0, 1).col, 12)
    1.0
    """
    y = np.asarray(mean_image)
    rows, cols = y.shape
    # one pass in float64 row blocks, about a first value (against cancellation in Σ y² − (Σ y)² / MN)
    shift = float(y[0, 0])
    total_sum, square_sum = 0.0, 0.0
    col_sums = np.zeros(cols)
    row_sums = []
    for block in _row_blocks(y):
        b = block.astype(np.float64)
        b -= shift
        row = b.sum(axis=1)
        row_sums.append(row)
        total_sum += float(row.sum())
        col_sums += b.sum(axis=0)
        square_sum += float(np.einsum("ij,ij->", b, b))
    return _split(total_sum, square_sum, np.concatenate(row_sums), col_sums, shift, temporal_var_dn2, frames)


def highpassed_variances(
    image: np.ndarray, temporal_var_dn2: float, frames: int, scale: float = 1.0, work: np.ndarray | None = None
) -> SpatialVariances:
    """``spatial_variances(scale · highpass(image), temporal_var_dn2, frames)`` without keeping the highpassed image:
    OpenCV's row, column and squared sums (double accumulators) of ``image`` − its smoothing, the §8.1 filter
    applied once (in float32). ``image`` (float32, or int16 as it is: exact integers make the best input) may be
    the sum of the L frames less an integer offset, ``scale`` = 1/L: the highpass is linear and removes constants,
    so that is the mean image's.
    ``work``: a float32 array of the image's shape to smooth into (else a fresh one).

    >>> img = np.random.default_rng(1).normal(0.0, 1.0, (40, 50))
    >>> a, b = highpassed_variances(2 * img + 9, 0.5, 2, 0.5), spatial_variances(highpass(img), 0.5, 2)
    >>> bool(np.isclose(a.total, b.total, rtol=1e-5) and np.isclose(a.row, b.row, rtol=1e-4))
    True
    """
    import cv2

    image = np.asarray(image)
    if image.dtype != np.int16:
        image = np.asarray(image, np.float32)
    m = HIGHPASS_MARGIN
    if min(image.shape) <= 2 * m + 1:
        raise ValueError(f"image {image.shape} too small for the EMVA 1288 highpass (needs > {2 * m + 1} px a side)")
    kernel = smoothing_kernel().astype(np.float32)
    smooth = cv2.sepFilter2D(image, cv2.CV_32F, kernel, kernel, dst=work, borderType=cv2.BORDER_REFLECT)
    inner = (slice(m, -m), slice(m, -m))
    y = smooth[inner]
    cv2.subtract(image[inner], y, dst=y, dtype=cv2.CV_32F)  # element by element: in place is safe
    row_sums = cv2.reduce(y, 1, cv2.REDUCE_SUM, dtype=cv2.CV_64F).ravel() * scale
    col_sums = cv2.reduce(y, 0, cv2.REDUCE_SUM, dtype=cv2.CV_64F).ravel() * scale
    square_sum = cv2.norm(y, cv2.NORM_L2SQR) * scale * scale
    return _split(float(row_sums.sum()), square_sum, row_sums, col_sums, 0.0, temporal_var_dn2, frames)


def _split(
    total_sum: float,
    square_sum: float,
    row_sums: np.ndarray,
    col_sums: np.ndarray,
    shift: float,
    temporal_var_dn2: float,
    frames: int,
) -> SpatialVariances:
    """Eq. 35–44 from the sums of an M×N image less ``shift``: its total, its squares, each row's and each column's
    sum."""
    rows, cols = row_sums.size, col_sums.size
    size = rows * cols
    mu = shift + total_sum / size
    measured = (square_sum - total_sum * total_sum / size) / size
    total = measured - temporal_var_dn2 / frames
    col_means = shift + col_sums / rows
    row_means = shift + row_sums / cols
    cav = float(np.mean((col_means - mu) ** 2)) - temporal_var_dn2 / (frames * rows)
    rav = float(np.mean((row_means - mu) ** 2)) - temporal_var_dn2 / (frames * cols)
    m, n = rows, cols
    det = m * n - m - n
    col = ((m * n - m) * cav - n * (total - rav)) / det
    row = ((m * n - n) * rav - m * (total - cav)) / det
    pixel = m * n * (total - cav - rav) / det
    return SpatialVariances(measured, total, cav, rav, row, col, pixel, rows, cols)


def _row_blocks(image: np.ndarray, pixels: int = 1 << 16) -> list[np.ndarray]:
    """Views of at most ``pixels`` pixels and an eighth of the image each (whole rows), to keep float64 and complex
    temporaries a fraction of a frame."""
    rows = max(1, min(pixels, image.size // 8) // image.shape[1])
    return [image[i : i + rows] for i in range(0, image.shape[0], rows)]


def dsnu_e(s2_dark_dn2: float, k_dn_per_e: float) -> float | None:
    """DSNU₁₂₈₈ = s_y.dark / K [e⁻] (eq. 66); None for a negative variance."""
    return math.sqrt(s2_dark_dn2) / k_dn_per_e if s2_dark_dn2 >= 0 else None


def prnu_percent(s2_bright_dn2: float, s2_dark_dn2: float, signal_dn: float) -> float | None:
    """PRNU₁₂₈₈ = 100 √(s²_y.50 − s²_y.dark) / (μ_y.50 − μ_y.dark) [%] (eq. 67); None for a negative radicand."""
    excess = s2_bright_dn2 - s2_dark_dn2
    return 100.0 * math.sqrt(excess) / signal_dn if excess >= 0 and signal_dn > 0 else None


def spectrogram(image: np.ndarray, vertical: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(spatial frequency v/N [cycles/pixel], √P[v] [DN]) for v = 0 … N/2 (eq. 70–71); ``vertical``: the same
    down the columns. White noise of variance s² gives a flat √P = s."""
    y = np.asarray(image)
    if vertical:
        y = y.T
    n = y.shape[1]
    mu = float(y.mean(dtype=np.float64))
    power = np.zeros(n // 2 + 1)
    for block in _row_blocks(y):
        spectrum = np.fft.rfft(block - mu, axis=1) / math.sqrt(n)
        power += np.sum(spectrum.real**2 + spectrum.imag**2, axis=0)
    return np.arange(power.size) / n, np.sqrt(power / y.shape[0])


def profiles(image: np.ndarray, vertical: bool = False) -> dict[str, np.ndarray]:
    """§8.7 profiles of an unfiltered image: ``middle`` (row M//2, or column N//2), ``mean``, ``max``, ``min`` over
    all rows (columns) at each horizontal (vertical) position."""
    y = np.asarray(image)
    if vertical:
        y = y.T
    return {
        "middle": y[y.shape[0] // 2].astype(np.float64),
        "mean": y.mean(axis=0, dtype=np.float64),
        "max": y.max(axis=0).astype(np.float64),
        "min": y.min(axis=0).astype(np.float64),
    }


@dataclass(frozen=True)
class Histogram:
    """A §8.8 histogram: bin centres as deviations from the mean [DN], counts, and the model curve with its standard
    deviation s_nw [DN] (normal density, logarithmic histogram; None for the accumulated one, in percent)."""

    centres_dn: np.ndarray
    counts: np.ndarray
    model: np.ndarray | None
    bin_width_dn: float
    spread_dn: float | None = None


def _bins(span: float, frames: int) -> tuple[int, int]:
    """(I, Q): the interval factor (eq. 73/78) and the number of bins of width I/L."""
    interval = math.floor(frames * span / HISTOGRAM_MAX_BINS) + 1
    return interval, math.floor(frames * span / interval) + 1


def _counts(blocks, origin: float, frames: int, interval: int, count: int, absolute: bool = False) -> np.ndarray:
    """Eq. 74 / 79 bin counts, q = floor(L (y − origin) / I) (of |y − origin| when ``absolute``), block by block."""
    counts = np.zeros(count, np.int64)
    for block in blocks:
        y = block.astype(np.float64)
        y -= origin
        if absolute:
            np.abs(y, out=y)
        index = np.minimum(np.floor(frames * y.ravel() / interval).astype(np.int64), count - 1)
        counts += np.bincount(index, minlength=count)
    return counts


def log_histogram(image: np.ndarray, frames: int) -> Histogram:
    """The logarithmic histogram of eq. 73–76 of a (highpassed) mean image of ``frames`` frames."""
    y = np.asarray(image)
    lo, hi, mu = float(y.min()), float(y.max()), float(y.mean(dtype=np.float64))
    interval, count = _bins(hi - lo, frames)
    counts = _counts(_row_blocks(y), lo, frames, interval, count)
    centres = lo + (interval - 1) / (2 * frames) + np.arange(count) * interval / frames - mu
    s_nw = math.sqrt(sum(float(np.sum((b.astype(np.float64) - mu) ** 2)) for b in _row_blocks(y)) / y.size)
    model = np.zeros(count)
    if s_nw > 0:
        model = (interval / frames) * y.size / (math.sqrt(2 * math.pi) * s_nw) * np.exp(-(centres**2) / (2 * s_nw**2))
    return Histogram(centres, counts, model, interval / frames, s_nw)


def accumulated_histogram(image: np.ndarray, frames: int) -> Histogram:
    """The accumulated histogram of |y − μ_y| of eq. 77–81, in percent of the pixels: at each bin, the share of
    pixels deviating by at least the bin's lower edge."""
    y = np.asarray(image)
    mu = float(y.mean(dtype=np.float64))
    top = max(abs(float(y.max()) - mu), abs(float(y.min()) - mu))
    interval, count = _bins(top, frames)
    counts = _counts(_row_blocks(y), mu, frames, interval, count, absolute=True)
    accumulated = np.cumsum(counts[::-1])[::-1] * (100.0 / y.size)
    centres = (interval - 1) / (2 * frames) + np.arange(count) * interval / frames
    return Histogram(centres, accumulated, None, interval / frames)


@dataclass(frozen=True)
class ImageAnalysis:
    """Spectrograms, profiles and histograms (§8.6–8.8) of the DSNU image ⟨y_dark⟩ and the PRNU image
    ⟨y_50⟩ − ⟨y_dark⟩. Spectrograms: {"horizontal"|"vertical": (frequency, √P)}, the DSNU ones in DN, the PRNU ones
    in percent of the mean photo-induced signal; profiles: {"horizontal"|"vertical": {middle, mean, max, min}} [DN];
    histograms: {"log"|"accumulated": `Histogram`}."""

    dsnu_spectrograms: dict
    prnu_spectrograms: dict
    dsnu_profiles: dict
    prnu_profiles: dict
    dsnu_histograms: dict
    prnu_histograms: dict
    signal_dn: float


def analyse_images(
    mean_bright: np.ndarray, mean_dark: np.ndarray, frames_bright: int, frames_dark: int
) -> ImageAnalysis:
    """`ImageAnalysis` of the mean images of a bright stack near 50 % of saturation and a dark stack (the two
    images analysed side by side in two threads: the FFTs and filters release the GIL)."""
    from concurrent.futures import ThreadPoolExecutor

    dark = np.asarray(mean_dark, np.float32)
    prnu = np.asarray(mean_bright, np.float32) - dark
    signal = float(prnu.mean())
    with ThreadPoolExecutor(2) as pool:
        prnu_job = pool.submit(_image_parts, prnu, min(frames_bright, frames_dark))
        dsnu_spectrograms, dsnu_profiles, dsnu_histograms = _image_parts(dark, frames_dark)
        prnu_spectrograms, prnu_profiles, prnu_histograms = prnu_job.result()
    return ImageAnalysis(
        dsnu_spectrograms=dsnu_spectrograms,
        prnu_spectrograms={name: (f, 100.0 * p / signal) for name, (f, p) in prnu_spectrograms.items()},
        dsnu_profiles=dsnu_profiles,
        prnu_profiles=prnu_profiles,
        dsnu_histograms=dsnu_histograms,
        prnu_histograms=prnu_histograms,
        signal_dn=signal,
    )


def _image_parts(image: np.ndarray, frames: int) -> tuple[dict, dict, dict]:
    """Spectrograms and histograms of the highpassed ``image``, profiles of ``image`` itself."""
    filtered = highpass(image)
    directions = {"horizontal": False, "vertical": True}
    return (
        {name: spectrogram(filtered, v) for name, v in directions.items()},
        {name: profiles(image, v) for name, v in directions.items()},
        {"log": log_histogram(filtered, frames), "accumulated": accumulated_histogram(filtered, frames)},
    )
