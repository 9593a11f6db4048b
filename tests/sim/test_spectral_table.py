"""The interpolated spectral integrals against the float64 sum over wavelength, closed forms, and independence of a
point's value from the grid it is evaluated in."""

import numpy as np
import pytest

from uwlab.model import design as design_module
from uwlab.model.design import (
    IMAGE_DIRECT_PATHS,
    build_design,
    electron_rate_at_radius,
    evaluate,
    image_radii_m,
    path_integrals,
    spectral_weights,
)
from uwlab.model.spectral_table import SpectralTable
from uwlab.model.water import WATER_TYPES

ACCURACY = 1e-8  # the tables are built to 1e-9 in ln F; the issue asks for 1e-4


@pytest.mark.parametrize("water", WATER_TYPES)
@pytest.mark.parametrize("spectrum", ["generic-led", "halogen", "daylight", "fluorescent"])
def test_path_integrals_match_the_wavelength_sum(example_raw, water, spectrum):
    example_raw["water"]["type"] = water
    example_raw["light"]["spectrum"] = spectrum
    weights = spectral_weights(build_design(example_raw))
    rng = np.random.default_rng(7)
    paths = np.concatenate([[0.0, 1e-6], rng.uniform(0, 5, 300), rng.uniform(5, 80, 300), rng.uniform(80, 400, 100)])
    exact = path_integrals(weights, paths)
    for column in range(3):
        assert weights.table(paths, column) == pytest.approx(exact[:, column], rel=ACCURACY)


def test_a_line_spectrum_is_exactly_exponential_at_any_length():
    """One wavelength: G(D) = w e^(−cD); ln G is linear, so the table is exact far past float underflow of e^(−cD)."""
    c = np.array([0.5, 0.05, 2.0])
    W = np.array([[0.0, 0.0, 0.0], [2.0, 3.0, 4.0], [0.0, 0.0, 0.0]])
    table = SpectralTable(c, W)
    paths = np.array([0.0, 1.0, 100.0, 1000.0, 5000.0])
    for column in range(3):
        log_g = np.log(table.table(paths, column))
        assert log_g == pytest.approx(np.log(W[1, column]) - 0.05 * paths, rel=1e-12, abs=1e-9)
        far = table.table.log(np.array([20000.0]), column)[0]
        assert far == pytest.approx(np.log(W[1, column]) - 1000.0, rel=1e-12)


def test_zero_weight_columns_stay_zero():
    c = np.array([0.1, 0.2])
    W = np.array([[1.0, 0.0, 0.5], [2.0, 0.0, 0.0]])
    table = SpectralTable(c, W)
    assert np.all(table(np.array([0.0, 3.0]), 1) == 0.0)
    assert table(np.array([3.0]), 2)[0] == pytest.approx(0.5 * np.exp(-0.3), rel=ACCURACY)


def test_a_point_has_the_same_bits_in_any_grid_and_any_build_order(example_raw):
    """Table nodes lie on a fixed lattice: the value at D does not depend on what else was asked, or when."""
    weights = spectral_weights(build_design(example_raw))
    first = SpectralTable(weights.c, weights.W)
    second = SpectralTable(weights.c, weights.W)
    probe = np.array([0.37, 2.5, 19.0, 150.0])
    alone = np.array([first(probe[i : i + 1], 2)[0] for i in range(probe.size)])
    second(np.linspace(0, 300, 100_003), 2)  # builds every block first, in another order
    together = second(np.concatenate([probe, np.linspace(0, 300, 50_000)]), 2)[: probe.size]
    assert alone.tobytes() == together.tobytes()


def _image_reference(design):
    rate = electron_rate_at_radius(design, image_radii_m(design.sensor)).mean(axis=-1)
    return rate


@pytest.mark.parametrize("port, model", [("flat", "cone"), ("dome", "cone"), ("flat", "disk")])
def test_image_average_through_the_cumulative_table_matches_the_wavelength_sum(example_raw, port, model):
    """Many path lengths for one geometry take the table route (one lookup per point); beams narrower than the
    field and narrower than every sample (zero light) included."""
    example_raw["water"]["type"] = "jerlov-5C"
    example_raw["lens"]["focal_length_mm"] = 6.0
    example_raw["light"]["beam_model"] = model
    example_raw["housing"].update(port=port, dome_radius_mm=60.0, dome_thickness_mm=6.0)
    base = build_design(example_raw)
    altitudes = np.linspace(0.2, 40.0, 2 * IMAGE_DIRECT_PATHS)
    betas = np.array([0.5, 3.0, 10.0, 25.0, 40.0, 89.0])
    grid = base.with_values(**{"operation.altitude_m": altitudes[:, None], "light.beam_half_angle_deg": betas[None, :]})
    weights = spectral_weights(grid)
    table = design_module._image_average_rate(grid, weights)
    reference = _image_reference(grid)
    assert np.all(table[:, 0] == 0) and np.all(reference[:, 0] == 0)
    assert table[:, 1:] == pytest.approx(reference[:, 1:], rel=ACCURACY)
    few_paths = grid.with_values(**{"operation.altitude_m": altitudes[:50, None]})
    direct = design_module._image_average_rate(few_paths, weights)
    assert direct == pytest.approx(table[:50], rel=ACCURACY)


def test_image_average_over_many_lens_geometries_matches_the_wavelength_sum(example_raw):
    example_raw["water"]["type"] = "jerlov-II"
    base = build_design(example_raw)
    grid = base.with_values(
        **{
            "lens.focal_length_mm": np.array([4.0, 8.0, 16.0, 50.0])[:, None, None],
            "housing.water_index": np.array([1.33, 1.34])[None, :, None],
            "operation.altitude_m": np.linspace(0.5, 12.0, 9)[None, None, :],
        }
    )
    out = design_module._image_average_rate(grid, spectral_weights(grid))
    assert out == pytest.approx(_image_reference(grid), rel=ACCURACY)


def test_image_average_over_many_beams_per_lens_geometry_matches_the_wavelength_sum(example_raw):
    """Many beam angles per path and geometry (the samples summed once per path, shared by the beams)."""
    example_raw["water"]["type"] = "jerlov-III"
    base = build_design(example_raw)
    grid = base.with_values(
        **{
            "lens.focal_length_mm": np.array([3.0, 8.0, 30.0])[:, None, None],
            "operation.altitude_m": np.array([0.4, 3.0, 20.0])[None, :, None],
            "light.beam_half_angle_deg": np.linspace(2.0, 88.0, 96)[None, None, :],
        }
    )
    out = design_module._image_average_rate(grid, spectral_weights(grid))
    assert out == pytest.approx(_image_reference(grid), rel=ACCURACY)


def _reference_in_pieces(design, keys, piece=200):
    """`_image_reference` of a 1-D design (every key an array of the same length), in pieces (it sums every
    sample × every wavelength)."""
    size = np.size(design[keys[0]])
    return np.concatenate(
        [
            _image_reference(design.with_values(**{k: design[k][s : s + piece] for k in keys}))
            for s in range(0, size, piece)
        ]
    )


@pytest.mark.parametrize(
    "port, model, water",
    [
        ("flat", "cone", "jerlov-II"),
        ("dome", "cone", "jerlov-5C"),
        ("flat", "disk", "pure-fresh"),
        ("flat", "cone", "jerlov-9C"),
    ],
)
def test_image_average_with_a_lens_geometry_per_point_matches_the_wavelength_sum(example_raw, port, model, water):
    """Every point its own focal length, water index, beam and path (the Gauss-rule route): narrow to very wide
    fields (f = 1 to 60 mm on a 2/3" sensor: up to 80° off axis) and paths to 300 m, against the float64 sum over
    every image sample and wavelength."""
    example_raw["water"]["type"] = water
    example_raw["light"]["beam_model"] = model
    example_raw["housing"].update(port=port, dome_radius_mm=60.0, dome_thickness_mm=6.0)
    rng = np.random.default_rng(11)
    n = 400
    values = {
        "lens.focal_length_mm": np.exp(rng.uniform(0.0, np.log(60.0), n)),
        "housing.water_index": rng.uniform(1.0, 1.5, n),
        "operation.altitude_m": np.exp(rng.uniform(np.log(0.1), np.log(150.0), n)),
        "light.beam_half_angle_deg": rng.uniform(1.0, 89.0, n),
    }
    grid = build_design(example_raw).with_values(**values)
    out = design_module._image_average_rate(grid, spectral_weights(grid))
    reference = _reference_in_pieces(grid, list(values))
    lit = reference > 1e-250  # the rest underflows in both (e^(−cD) past float64 at long paths in turbid water)
    assert lit.sum() > n // 2 and np.all(out[~lit] < 1e-250)
    assert out[lit] == pytest.approx(reference[lit], rel=ACCURACY)


def test_a_grid_with_a_lens_geometry_per_point_equals_point_by_point(example_raw):
    """altitude × focal length × water index × beam (the benchmark's geometry_per_point grid, small) against
    scalar evaluations of every point."""
    example_raw["operation"]["exposure_s"] = 1e-4
    base = build_design(example_raw)
    axes = {
        "operation.altitude_m": np.array([0.5, 3.0, 10.0]),
        "lens.focal_length_mm": np.array([2.0, 4.0, 12.0, 50.0]),
        "housing.water_index": np.array([1.33, 1.34, 1.35]),
        "light.beam_half_angle_deg": np.array([15.0, 60.0]),
    }
    shaped = {k: v.reshape([-1 if i == j else 1 for j in range(4)]) for i, (k, v) in enumerate(axes.items())}
    out = evaluate(base.with_values(**shaped))
    for index in np.ndindex(3, 4, 3, 2):
        point = evaluate(base.with_values(**{k: float(v[i]) for (k, v), i in zip(axes.items(), index, strict=True)}))
        assert np.broadcast_to(out["mean_electrons"], (3, 4, 3, 2))[index] == pytest.approx(
            float(point["mean_electrons"]), rel=1e-12
        )
        for key in ("mean_electrons", "mean_dn", "snr"):
            assert out["image_average"][key][index] == pytest.approx(float(point["image_average"][key]), rel=1e-12)


def test_grid_evaluation_equals_point_by_point(example_raw):
    """The hard grid (every point its own spectral path) against scalar evaluations of sampled points."""
    example_raw["operation"]["exposure_s"] = 1e-4
    base = build_design(example_raw)
    axes = {
        "operation.altitude_m": np.linspace(0.5, 10.0, 40),
        "water.attenuation_scale": np.linspace(0.5, 2.0, 30),
        "light.beam_half_angle_deg": np.linspace(10.0, 60.0, 20),
    }
    shaped = {k: v.reshape([-1 if i == j else 1 for j in range(3)]) for i, (k, v) in enumerate(axes.items())}
    out = evaluate(base.with_values(**shaped))
    rng = np.random.default_rng(3)
    for index in zip(*(rng.integers(0, v.size, 6) for v in axes.values()), strict=True):
        point = evaluate(base.with_values(**{k: float(v[i]) for (k, v), i in zip(axes.items(), index, strict=True)}))
        assert out["mean_electrons"][index] == pytest.approx(float(point["mean_electrons"]), rel=1e-12)
        assert out["image_average"]["mean_electrons"][index] == pytest.approx(
            float(point["image_average"]["mean_electrons"]), rel=ACCURACY
        )
