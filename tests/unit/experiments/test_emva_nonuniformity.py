"""Release 4.0 spatial nonuniformity against closed forms: the §8.1 highpass (the three filters, its gains for white
pixel and line patterns, smooth illumination removed), the row/column/pixel split of eq. 44, spectrograms (eq. 70-72),
profiles and histograms (eq. 73-81), and the streaming statistics (eq. 18, 35, 65)."""

import numpy as np
import pytest
from scipy.ndimage import uniform_filter

from uwlab.errors import ConfigError
from uwlab.experiments.frames.nonuniformity import (
    HIGHPASS_MARGIN,
    accumulated_histogram,
    highpass,
    line_noise_gain,
    log_histogram,
    profiles,
    spatial_variances,
    spectrogram,
    white_noise_gain,
)
from uwlab.experiments.frames.stack import StackAccumulator, stack_statistics


def test_highpass_is_the_three_filters_subtracted():
    """7×7 box, then 11×11 box, then 3×3 binomial (§8.1), each applied by scipy, subtracted from the image."""
    rng = np.random.default_rng(3)
    image = rng.normal(100.0, 5.0, (70, 90))
    smooth = uniform_filter(uniform_filter(image, 7, mode="reflect"), 11, mode="reflect")
    binomial = np.outer([1, 2, 1], [1, 2, 1]) / 16.0
    from scipy.ndimage import convolve

    smooth = convolve(smooth, binomial, mode="reflect")
    m = HIGHPASS_MARGIN
    np.testing.assert_allclose(highpass(image), (image - smooth)[m:-m, m:-m], atol=1e-4)


def test_highpass_gains_for_white_patterns():
    rng = np.random.default_rng(4)
    pixels = rng.standard_normal((1200, 1200))
    assert highpass(pixels).var() == pytest.approx(white_noise_gain(), rel=0.01)
    columns = np.tile(rng.standard_normal(60000), (20, 1))
    assert highpass(columns).var() == pytest.approx(line_noise_gain(), rel=0.02)


def test_highpass_removes_smooth_illumination():
    """A strong smooth falloff (30 % cos⁴-like vignetting over the image) leaves almost nothing after the highpass:
    a quadratic surface becomes a constant, a linear one vanishes."""
    y, x = np.mgrid[0:200, 0:300]
    r2 = ((x - 150) ** 2 + (y - 100) ** 2) / 180.0**2
    vignetted = 3000.0 * (1 - 0.3 * r2)
    assert highpass(vignetted).std() < 1e-3
    assert np.abs(highpass(2.0 * x + 3.0 * y)).max() < 1e-3


def test_split_recovers_row_column_and_pixel_patterns():
    """Eq. 44 of r[m] + c[n] + p[m, n] with known variances (sample variances, exact up to cross terms)."""
    rng = np.random.default_rng(5)
    rows, cols = 600, 800
    r = rng.normal(0, 2.0, rows)
    c = rng.normal(0, 3.0, cols)
    p = rng.normal(0, 1.5, (rows, cols))
    s = spatial_variances(r[:, None] + c[None, :] + p, 0.0, 1)
    assert s.row == pytest.approx(4.0, rel=0.15)
    assert s.col == pytest.approx(9.0, rel=0.12)
    assert s.pixel == pytest.approx(2.25, rel=0.02)
    assert s.row + s.col + s.pixel == pytest.approx(s.total, rel=1e-12)


def test_split_removes_the_temporal_noise_of_the_mean_image():
    """Temporal noise σ² averaged over L frames contributes σ²/L to the pixel part, σ²/(L M) and σ²/(L N) to the mean
    column and row: eq. 36 and 41 remove them, leaving zero for a pattern-free image."""
    rng = np.random.default_rng(6)
    frames, var = 8, 25.0
    mean_image = rng.normal(0, np.sqrt(var / frames), (500, 700))
    s = spatial_variances(mean_image, var, frames)
    for part in (s.total, s.row, s.col, s.pixel):
        assert abs(part) < 0.05 * var / frames


def test_spectrogram_white_level_and_sinusoid_amplitude():
    rng = np.random.default_rng(7)
    white = rng.normal(0, 2.0, (400, 512))
    freq, amp = spectrogram(white)
    assert freq[-1] == pytest.approx(0.5) and amp.size == 257
    assert np.mean(amp[1:]) == pytest.approx(2.0, rel=0.03)
    # a column pattern of amplitude 1.5 at 0.125 cycles/pixel: eq. 72, a = 2 (Σ P / N)^½ over its peak
    n = 512
    pattern = np.tile(1.5 * np.sin(2 * np.pi * 0.125 * np.arange(n)), (50, 1))
    freq, amp = spectrogram(pattern)
    peak = int(np.argmax(amp))
    assert freq[peak] == pytest.approx(0.125)
    assert 2 * np.sqrt(amp[peak] ** 2 / n) == pytest.approx(1.5, rel=1e-9)
    _, vertical = spectrogram(pattern, vertical=True)
    assert vertical[1:].max() < 1e-9


def test_profiles():
    image = np.arange(12.0).reshape(3, 4)
    h = profiles(image)
    np.testing.assert_array_equal(h["middle"], image[1])
    np.testing.assert_array_equal(h["max"], image[2])
    np.testing.assert_array_equal(h["mean"], image.mean(axis=0))
    v = profiles(image, vertical=True)
    np.testing.assert_array_equal(v["middle"], image[:, 2])
    np.testing.assert_array_equal(v["min"], image[:, 0])


def test_histograms():
    rng = np.random.default_rng(8)
    frames = 4
    image = np.round(rng.normal(0, 3.0, (300, 300)) * frames) / frames  # values on the 1/L grid
    log = log_histogram(image, frames)
    assert log.counts.sum() == image.size and log.counts.size <= 256
    span = image.max() - image.min()
    interval = int(np.floor(frames * span / 256)) + 1  # eq. 73
    assert log.bin_width_dn == pytest.approx(interval / frames)
    assert log.spread_dn == pytest.approx(image.std())
    assert log.model.sum() == pytest.approx(image.size, rel=0.02)  # the normal density integrates to N M
    acc = accumulated_histogram(image, frames)
    assert acc.counts[0] == pytest.approx(100.0)  # every pixel deviates by at least 0
    assert np.all(np.diff(acc.counts) <= 0)
    outliers = image.copy()
    outliers[0, :3] = 100.0
    assert accumulated_histogram(outliers, frames).counts[-1] == pytest.approx(100 * 3 / image.size)


def test_stack_statistics_closed_form():
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 4096, (30, 40), dtype=np.uint16) for _ in range(5)]
    frames[4][0, :3] = 4095
    stats = stack_statistics(iter(frames), 4095)
    stack = np.array(frames, float)
    pairs = [
        0.5 * (np.mean((stack[i] - stack[i + 1]) ** 2) - (stack[i].mean() - stack[i + 1].mean()) ** 2) for i in (0, 2)
    ]
    assert stats.frames == 5
    assert stats.mean_dn == pytest.approx(stack.mean())
    assert stats.temporal_var_dn2 == pytest.approx(np.mean(pairs))  # eq. 18
    assert stats.stack_var_dn2 == pytest.approx(stack.var(axis=0, ddof=1).mean())  # eq. 65
    assert stats.spatial_var_dn2 == pytest.approx(stack.mean(axis=0).var())  # eq. 35
    assert stats.mean_diff_dn == pytest.approx(stack[0].mean() - stack[1].mean())
    assert stats.saturated_fraction == pytest.approx(np.any(stack == 4095, axis=0).mean())
    expected = spatial_variances(highpass(stack.mean(axis=0)), stack.var(axis=0, ddof=1).mean(), 5)
    assert stats.spatial.total == pytest.approx(expected.total, rel=1e-5)


@pytest.mark.parametrize("top", [4096, 65536])
@pytest.mark.parametrize("count", [2, 3, 4, 7])
def test_stack_variance_is_exact_for_every_stack_length(count, top):
    """Eq. 65 to the last bit whatever L: each pair's sums of squares from its sum (12-bit values) or from its
    frames (16-bit values far from the integer centre), an odd last frame's alone."""
    rng = np.random.default_rng(count)
    frames = [rng.integers(0, top, (33, 41), dtype=np.uint16) for _ in range(count)]
    stack = np.array(frames, np.float64)
    stats = stack_statistics(iter(frames), top - 1)
    assert stats.stack_var_dn2 == pytest.approx(stack.var(axis=0, ddof=1).mean(), rel=1e-12)


def test_mean_difference_correction_of_eq_18():
    """A common offset between the two frames (all pixels in sync) does not enter σ²_y."""
    rng = np.random.default_rng(9)
    a = rng.integers(1000, 1100, (40, 50)).astype(np.uint16)
    b = (a + 7).astype(np.uint16)
    assert stack_statistics([a, b], 4095).temporal_var_dn2 == pytest.approx(0.0, abs=1e-12)


def test_stack_statistics_needs_a_pair():
    acc = StackAccumulator(255)
    acc.add(np.zeros((4, 4), np.uint8))
    with pytest.raises(ConfigError, match="frames"):
        acc.result()


@pytest.mark.parametrize(
    ("dtype", "top", "shape"),
    [
        (np.uint8, 255, (40000, 3)),
        (np.uint8, 255, (1, 70001)),
        (np.uint16, 4095, (2048, 61)),
        (np.uint16, 8190, (1100, 1000)),
        (np.uint16, 46340, (300, 7)),
        (np.uint16, 65535, (70, 9)),
        (np.uint16, 46340, (600, 450)),  # Σ y² ≥ 2^49: not OpenCV's norm but its pieces (of one row)
        (np.uint16, 65535, (400, 331)),  # Σ y² ≥ 2^49 and y² ≥ 2^31: int64
        (np.int16, 32767, (50, 11)),
        (np.int32, 1 << 20, (20, 13)),
    ],
)
def test_frame_sums_are_exact_at_their_bounds(dtype, top, shape):
    """Σ y, Σ y² and a pair's Σ (a − b)² to the last unit, the pixels at the top code (every partial sum as large
    as the piece rules allow: 2^31 / 8190² = 32 rows of 2048 columns) and random, contiguous or not, whatever
    routine the type takes (OpenCV's squared norm, OpenCV over pieces of the image's memory, with elements left
    over, or int64)."""
    from uwlab.experiments.frames.stack import _diff_square_sum, _sums, _total

    rng = np.random.default_rng(top)
    full = np.full(shape, top, dtype)
    noisy = rng.integers(0, top + 1, shape).astype(dtype)
    pairs = ((full, np.zeros(shape, dtype)), (noisy, full), (noisy, noisy[::-1].copy()), (noisy[:, 1:], full[:, 1:]))
    for a, b in pairs:
        x, y = a.astype(object), b.astype(object)
        assert _sums(a, top) == (int(x.sum()), int((x * x).sum()))
        assert _total(a, top) == int(x.sum())
        assert _diff_square_sum(a, b, top) == int(((x - y) ** 2).sum())


def test_highpassed_variances_of_a_sum_image():
    """The split of a stack's highpassed mean image, from the sum image less an integer offset (float32, exact) and
    a scale 1/L, agrees with the highpass of the mean image itself."""
    from uwlab.experiments.frames.nonuniformity import highpassed_variances

    rng = np.random.default_rng(11)
    frames = 3
    total = rng.integers(3000, 9000, (64, 80)) + np.arange(80)[None, :] % 5
    expected = spatial_variances(highpass(total / frames), 4.0, frames)
    got = highpassed_variances((total - 18000).astype(np.float32), 4.0, frames, 1.0 / frames)
    for name in ("measured", "total", "cav", "rav", "row", "col", "pixel"):
        assert getattr(got, name) == pytest.approx(getattr(expected, name), rel=1e-5), name


@pytest.mark.parametrize(
    ("dtype", "low", "high"), [(np.uint8, 0, 256), (np.uint16, 0, 4096), (np.uint16, 50000, 65536)]
)
def test_pair_highpass_split_whatever_the_route(dtype, low, high):
    """A photon-transfer pair's highpassed split (the pair's sum less 2c filtered as int16 when its values allow,
    as float32 otherwise) agrees with the split of the highpassed mean image."""
    rng = np.random.default_rng(high)
    frames = [rng.integers(low, high, (45, 61)).astype(dtype) for _ in range(2)]
    stats = stack_statistics(frames, high - 1)
    stack = np.array(frames, np.float64)
    expected = spatial_variances(highpass(stack.mean(axis=0)), stats.temporal_var_dn2, 2)
    for name in ("measured", "total", "cav", "rav", "row", "col", "pixel"):
        assert getattr(stats.spatial, name) == pytest.approx(getattr(expected, name), rel=1e-5, abs=1e-9), name


@pytest.mark.parametrize("top", [4096, 65536])
@pytest.mark.parametrize("count", [2, 3, 4, 5])
@pytest.mark.parametrize("keep_mean_image", [False, True])
def test_stable_frames_from_two_alternating_buffers(count, top, keep_mean_image):
    """Frames read into two buffers in turn (a descriptor reader's ``stable_frames``: nothing copied, each buffer
    overwritten by the frame after next) give the statistics of the frames themselves: eq. 18, 35, 65, the mean
    image and the highpassed split of the mean image (12-bit frames take the pair-sum route, 16-bit ones keep the
    first pair's frames)."""
    from uwlab.experiments.frames.stack import WorkImages

    rng = np.random.default_rng(count * top)
    frames = [rng.integers(0, top, (37, 45), dtype=np.uint16) for _ in range(count)]
    buffers = [np.empty((37, 45), np.uint16) for _ in range(2)]

    def read():
        for i, frame in enumerate(frames):
            np.copyto(buffers[i % 2], frame)
            yield buffers[i % 2]

    stats = stack_statistics(read(), top - 1, keep_mean_image, work=WorkImages(), stable_frames=True)
    stack = np.array(frames, np.float64)
    pairs = [
        0.5 * (np.mean((stack[i] - stack[i + 1]) ** 2) - (stack[i].mean() - stack[i + 1].mean()) ** 2)
        for i in range(0, count - 1, 2)
    ]
    assert stats.temporal_var_dn2 == pytest.approx(np.mean(pairs), rel=1e-12)  # eq. 18
    assert stats.stack_var_dn2 == pytest.approx(stack.var(axis=0, ddof=1).mean(), rel=1e-12)  # eq. 65
    assert stats.spatial_var_dn2 == pytest.approx(stack.mean(axis=0).var(), rel=1e-9)  # eq. 35
    assert stats.mean_diff_dn == pytest.approx(stack[0].mean() - stack[1].mean(), abs=1e-9)
    split = stats.stack_var_dn2 if count > 2 else stats.temporal_var_dn2
    expected = spatial_variances(highpass(stack.mean(axis=0)), split, count)
    for name in ("measured", "total", "row", "col", "pixel"):
        assert getattr(stats.spatial, name) == pytest.approx(getattr(expected, name), rel=1e-5, abs=1e-6), name
    if keep_mean_image:
        np.testing.assert_allclose(stats.mean_image, stack.mean(axis=0), rtol=0, atol=4 * np.spacing(np.float32(top)))
