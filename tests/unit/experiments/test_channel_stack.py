"""Per colour channel statistics of a raw Bayer stack (`StackAccumulator` with ``bayer``) and their dataset columns.

Truth: synthetic mosaics whose every colour site is drawn from its own known distribution (mean and temporal
standard deviation per colour, a known count of sites at the clip level), so each channel's statistics have closed
forms the accumulator never sees; the phase of a crop at an odd offset is checked by cropping the same frames; fixed
patterns of known variance on each site (pixel, row and column parts) for each channel's highpassed split.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from uwlab.experiments.dataset import CHANNEL_FIELDS, POINT_SCHEMA, point_row
from uwlab.experiments.dataset_store import conform
from uwlab.experiments.frames.stack import stack_statistics
from uwlab.experiments.saturation import ClipLevel

# RGGB: R at (0, 0), G at (0, 1) and (1, 0), B at (1, 1)
TRUTH = {"R": (300.0, 4.0), "G": (900.0, 7.0), "B": (500.0, 5.0)}
SITES = {"R": ((0, 0),), "G": ((0, 1), (1, 0)), "B": ((1, 1),)}
CLIP_DN = 4095


def mosaics(count: int, shape=(64, 96), seed=1, saturate_green_rows: int = 0):
    """``count`` RGGB frames: each colour's sites N(mean, sd²) independently per frame, integers; the green sites of
    the first ``saturate_green_rows`` cell rows at the clip level in every frame."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        frame = np.empty(shape, np.uint16)
        for colour, (mean, sd) in TRUTH.items():
            for row, col in SITES[colour]:
                plane = frame[row::2, col::2]
                plane[...] = np.rint(rng.normal(mean, sd, plane.shape))
        for row, col in SITES["G"]:
            frame[row : 2 * saturate_green_rows : 2, col::2] = CLIP_DN
        yield frame


def test_each_channel_has_its_own_mean_and_temporal_variance():
    stats = stack_statistics(mosaics(8), CLIP_DN, bayer="RG")
    assert stats.channels is not None and set(stats.channels) == {"R", "G", "B"}
    for colour, (mean, sd) in TRUTH.items():
        channel = stats.channels[colour]
        sites = 64 * 96 // 4 * len(SITES[colour])
        assert channel.pixels == sites and channel.frames == 8
        assert channel.mean_dn == pytest.approx(mean, abs=5 * sd / np.sqrt(8 * sites))
        # temporal variance of a rounded normal: σ² + 1/12 (quantisation); 4 pairs × the sites, ~1.5 % standard error
        assert channel.temporal_var_dn2 == pytest.approx(sd**2 + 1 / 12, rel=0.07)
        # no fixed pattern: the highpassed split of each channel's site planes, corrected for the temporal noise,
        # is about zero (a part's noise is ~σ²/(L·√sites))
        assert channel.spatial is not None
        for part in (channel.spatial.row, channel.spatial.col, channel.spatial.pixel):
            assert abs(part) < 0.2 * sd**2 / 8
    # the mosaic pools the channels: its mean is their site-weighted mean, and its spatial variance holds the spread
    # between the channel means, which no channel's does
    assert stats.mean_dn == pytest.approx((TRUTH["R"][0] + 2 * TRUTH["G"][0] + TRUTH["B"][0]) / 4, abs=0.5)
    assert stats.spatial_var_dn2 > 50_000 > max(c.spatial_var_dn2 for c in stats.channels.values())


def test_a_crop_at_an_odd_offset_keeps_the_channels_apart():
    frames = list(mosaics(4))
    whole = stack_statistics(frames, CLIP_DN, bayer="RG")
    shifted = stack_statistics((f[1:, 1:] for f in frames), CLIP_DN, bayer="RG", origin=(1, 1))
    for colour, (mean, _) in TRUTH.items():
        assert shifted.channels[colour].mean_dn == pytest.approx(mean, abs=0.5)
        assert shifted.channels[colour].mean_dn == pytest.approx(whole.channels[colour].mean_dn, abs=0.5)
    # read with the wrong phase, red would be blue
    wrong = stack_statistics((f[1:, 1:] for f in frames), CLIP_DN, bayer="RG")
    assert wrong.channels["R"].mean_dn == pytest.approx(TRUTH["B"][0], abs=0.5)


def test_saturation_is_counted_per_channel_at_the_one_clip_level():
    stats = stack_statistics(mosaics(2, saturate_green_rows=4), CLIP_DN, bayer="RG")
    cell_rows = 64 // 2
    assert stats.channels["G"].saturated_fraction == pytest.approx(4 / cell_rows)
    assert stats.channels["R"].saturated_fraction == stats.channels["B"].saturated_fraction == 0.0
    assert stats.saturated_fraction == pytest.approx(2 * 4 / cell_rows / 4)


def test_each_channel_splits_its_own_fixed_patterns():
    """Fixed patterns (no temporal noise) of known variance per site: a pixel pattern on every site (red σ 20, the
    two green sites σ 10 and 30, blue σ 40), a row pattern on red only (σ 15) and a column pattern on blue only
    (σ 25). Each channel's split finds its own: green the mean of its two sites' (500 DN²); no channel sees
    another's rows or columns. Tolerances: a row part over 300 plane rows has a relative standard error of
    √(2/300) ≈ 8 % (25 % is 3σ), a column part over 400 columns 7 % (20 %), a pixel part over 120 000 sites 0.4 %
    (3 %, the highpass's edge effects included)."""
    rng = np.random.default_rng(8)
    frame = np.full((600, 800), 1000.0)
    for (row, col), sd in {(0, 0): 20.0, (0, 1): 10.0, (1, 0): 30.0, (1, 1): 40.0}.items():
        frame[row::2, col::2] += rng.normal(0.0, sd, (300, 400))
    frame[0::2, 0::2] += rng.normal(0.0, 15.0, (300, 1))
    frame[1::2, 1::2] += rng.normal(0.0, 25.0, (1, 400))
    mosaic = np.rint(frame).astype(np.uint16)
    channels = stack_statistics([mosaic, mosaic], CLIP_DN, bayer="RG").channels
    expected = {"R": (20.0**2, 15.0**2, 0.0), "G": ((10.0**2 + 30.0**2) / 2, 0.0, 0.0), "B": (40.0**2, 0.0, 25.0**2)}
    for colour, (pixel, row_var, col_var) in expected.items():
        split = channels[colour].spatial
        assert split.pixel == pytest.approx(pixel, rel=0.03), colour
        assert split.row == pytest.approx(row_var, rel=0.25, abs=0.02 * pixel), colour
        assert split.col == pytest.approx(col_var, rel=0.2, abs=0.02 * pixel), colour


def test_a_mono_stack_has_no_channels():
    assert stack_statistics(mosaics(2), CLIP_DN).channels is None


def row(bright, dark, **columns):
    return point_row(
        sweep_id="s",
        point_index=0,
        kind="exposure",
        bright=bright,
        dark=dark,
        clip=ClipLevel(CLIP_DN, "adc"),
        **columns,
    )


def test_point_row_records_each_channel_bright_minus_dark():
    bright = stack_statistics(mosaics(4), CLIP_DN, bayer="RG")
    dark = stack_statistics(mosaics(4, seed=2), CLIP_DN, bayer="RG")
    r = row(bright, dark, bayer="RG")
    for colour, name in (("R", "red"), ("G", "green"), ("B", "blue")):
        assert r[f"{name}_signal_dn"] == bright.channels[colour].mean_dn - dark.channels[colour].mean_dn
        assert r[f"{name}_dark_mean_dn"] == pytest.approx(TRUTH[colour][0], abs=0.5)
        assert r[f"{name}_pixels"] == bright.channels[colour].pixels and r[f"{name}_saturated"] is False
    mono = row(stack_statistics(mosaics(2), CLIP_DN), None)
    assert mono["bayer"] is None and all(mono[name] is None for name, _ in CHANNEL_FIELDS)


def test_points_written_before_the_channel_columns_still_read():
    new = ("bayer", *(name for name, _ in CHANNEL_FIELDS))
    old_schema = pa.schema([f for f in POINT_SCHEMA if f.name not in new])
    old = {name: None for name in old_schema.names} | {"sweep_id": "a", "point_index": 0, "mean_dn": 812.5}
    table = conform(pa.Table.from_pylist([old], schema=old_schema), POINT_SCHEMA)
    assert table.schema == POINT_SCHEMA and table.column("mean_dn").to_pylist() == [812.5]
    assert all(table.column(name).to_pylist() == [None] for name in new)
