"""EMVA 1288 Release 4.0 Linear analysis against closed forms: exact recovery from noise-free model statistics, the
sensitivity threshold as the root of SNR = 1, the linearity error against an independent regression, the saturation
rules (including the reference implementation's past-saturation pick), the dark current, and bad input."""

import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

from uwlab.errors import ConfigError
from uwlab.experiments.emva.analysis import characterize
from uwlab.experiments.emva.dark import DarkSeries
from uwlab.experiments.emva.from_dataset import photon_transfer_from_points
from uwlab.experiments.emva.linear import linearity_fit
from uwlab.experiments.emva.regression import fit_line
from uwlab.experiments.emva.transfer import (
    PER_POINT,
    RULE_CLIP,
    RULE_VARIANCE,
    PhotonTransfer,
    SpatialSplit,
    photons_per_pixel,
)
from uwlab.model.photometry import C_M_S, H_J_S, photon_flux, photons_per_joule
from tests.support.paths import DATA

K, ETA, SIGMA_D, SAT_E, DARK_E_S, OFFSET, DSNU_E, PRNU = 0.5, 0.6, 3.0, 8000.0, 100.0, 40.0, 2.0, 0.01
DATA = DATA


DARK_EXPOSURES = np.linspace(0.1, 0.6, 6)


def model_transfer(n=40, dark_exposures=DARK_EXPOSURES, temperature=None) -> PhotonTransfer:
    """Noise-free EMVA statistics of a linear camera (method I); the variance collapses past saturation."""
    t = np.linspace(0.001, 0.02, n)
    photons = 1.0e6 * t  # 1000 .. 20000 photons, full well at 13333
    mu_e = np.minimum(ETA * photons, SAT_E)
    sat = ETA * photons > SAT_E
    dark_mean = lambda tt: OFFSET + K * DARK_E_S * tt  # noqa: E731
    dark_var = lambda tt: K**2 * (SIGMA_D**2 + DARK_E_S * tt) + 1 / 12  # noqa: E731
    var = np.where(sat, 0.1, dark_var(t) + K**2 * mu_e)
    zeros = np.zeros(n)
    dark_pixel = np.full(n, (K * DSNU_E) ** 2)
    all_t = np.r_[t, dark_exposures]
    return PhotonTransfer(
        photons=photons,
        exposure_s=t,
        mean_dn=dark_mean(t) + K * mu_e,
        temporal_var_dn2=var,
        frames=np.full(n, 2.0),
        dark_mean_dn=dark_mean(t),
        dark_temporal_var_dn2=dark_var(t),
        dark_frames=np.full(n, 2.0),
        spatial=SpatialSplit(zeros, zeros, dark_pixel + (PRNU * K * mu_e) ** 2),
        dark_spatial=SpatialSplit(zeros, zeros, dark_pixel),
        dark=DarkSeries(
            all_t,
            dark_mean(all_t),
            dark_var(all_t),
            np.full(all_t.size, np.nan if temperature is None else temperature),
        ),
        bit_depth=12,
        saturated_fraction=np.where(sat, 1.0, 0.0),
        temperature_c=None if temperature is None else np.full(n, temperature),
    )


def test_photon_irradiance_closed_forms():
    # a flat 1 W/m²/nm spectrum over 400-600 nm: ∫ λ/(hc) dλ = (600² - 400²)/2 nm² · 1e-9 / (h c)
    nm = np.linspace(400, 600, 2001)
    expected = (600**2 - 400**2) / 2 * 1e-9 / (H_J_S * C_M_S)
    assert photon_flux(nm, np.ones_like(nm)) == pytest.approx(expected, rel=1e-9)
    assert photons_per_joule(500.0) == pytest.approx(500e-9 / (H_J_S * C_M_S))
    # Release 4.0 Linear eq. 4: μ_p = 50.34 A[µm²] t[ms] λ[µm] E[µW/cm²]
    area_um2, t_ms, lam_um, e_uw_cm2 = 11.9, 2.0, 0.525, 30.0
    mu_p = photons_per_pixel(e_uw_cm2 * 1e-2 * photons_per_joule(525.0), t_ms * 1e-3, area_um2 * 1e-12)
    assert mu_p == pytest.approx(50.34 * area_um2 * t_ms * lam_um * e_uw_cm2, rel=2e-4)


def test_fit_line_exact_and_noisy():
    x = np.arange(1.0, 11.0)
    exact = fit_line(x, 3.0 * x + 2.0)
    assert (exact.slope, exact.intercept) == pytest.approx((3.0, 2.0))
    assert exact.slope_std == pytest.approx(0.0, abs=1e-9)
    rng = np.random.default_rng(1)
    y = 3.0 * x + rng.normal(0, 0.5, x.size)
    fit = fit_line(x, y, through_origin=True)
    slope_std = math.sqrt(np.sum((y - fit.slope * x) ** 2) / (x.size - 1) / np.sum(x**2))
    assert fit.slope == pytest.approx(np.sum(x * y) / np.sum(x * x))
    assert fit.slope_std == pytest.approx(slope_std)


def test_exact_model_is_recovered():
    v = characterize(model_transfer()).values
    assert v["K_dn_per_e"] == pytest.approx(K, rel=1e-9)
    assert v["photon_transfer_offset_dn2"] == pytest.approx(0.0, abs=1e-6)
    assert v["quantum_efficiency"] == pytest.approx(ETA, rel=1e-9)
    # σ_d at the lowest exposure (eq. 53): the dark current's shot noise is part of it
    t0 = 0.001
    assert v["dark_noise_e"] == pytest.approx(math.sqrt(SIGMA_D**2 + DARK_E_S * t0), rel=1e-9)
    assert v["dark_current_e_per_s"] == pytest.approx(DARK_E_S, rel=1e-9)
    assert v["dark_current_var_e_per_s"] == pytest.approx(DARK_E_S, rel=1e-9)
    assert v["dsnu_e"] == pytest.approx(DSNU_E, rel=1e-9)
    assert v["dsnu_pixel_e"] == pytest.approx(DSNU_E, rel=1e-6)
    assert v["dsnu_row_e"] == pytest.approx(0.0, abs=1e-6) and v["prnu_col_percent"] == pytest.approx(0.0, abs=1e-6)
    assert v["linearity_error_percent"] == pytest.approx(0.0, abs=1e-9)
    assert v["photon_transfer_slope_deviation"] == pytest.approx(0.0, abs=1e-6)
    assert v["dark_offset_dn"] == pytest.approx(OFFSET)
    # saturation (§6.6): the last point before the first one with pixels at the clip level
    photons = 1.0e6 * np.linspace(0.001, 0.02, 40)
    assert v["saturation_rule"] == RULE_CLIP
    assert v["saturation_e"] == pytest.approx(ETA * photons[ETA * photons <= SAT_E].max())
    assert v["snr_max"] == pytest.approx(math.sqrt(v["saturation_e"]))
    assert v["snr_max_db"] == pytest.approx(10 * math.log10(v["saturation_e"]))


def test_prnu_of_the_50_percent_point_is_the_simulated_one():
    v = characterize(model_transfer()).values
    assert v["prnu_percent"] == pytest.approx(100 * PRNU, rel=1e-9)
    assert v["nonuniformity_source"].startswith("sweep point")


def test_sensitivity_threshold_is_the_root_of_snr_one():
    """μ_p.min (eq. 26) solves η μ_p / √(σ²_y.dark/K² + η μ_p) = 1 (eq. 21 with σ²_y.dark = K²σ_d² + σ_q²); μ_e.min is
    η μ_p.min (eq. 27) and DR is μ_p.sat over it (eq. 28)."""
    v = characterize(model_transfer()).values
    dark_var = K**2 * (SIGMA_D**2 + DARK_E_S * 0.001) + 1 / 12
    root = brentq(lambda p: ETA * p / math.sqrt(dark_var / K**2 + ETA * p) - 1.0, 1e-3, 1e3, xtol=1e-13)
    assert v["sensitivity_threshold_photons"] == pytest.approx(root, rel=1e-9)
    assert v["sensitivity_threshold_e"] == pytest.approx(ETA * root, rel=1e-9)
    assert v["dynamic_range"] == pytest.approx(v["saturation_photons"] / root, rel=1e-9)
    assert v["dynamic_range_db"] == pytest.approx(20 * math.log10(v["dynamic_range"]), rel=1e-12)


def test_small_dark_variance_is_floored_at_0_49_dn():
    pt = model_transfer()
    dark = replace(pt.dark, var_dn2=np.full(len(pt.dark), 0.1))
    v = characterize(replace(pt, dark=dark)).values
    assert v["dark_noise_dn"] == pytest.approx(0.49)
    assert v["dark_noise_upper_limit"] is True
    assert v["dark_noise_e"] == pytest.approx(math.sqrt(0.49**2 - 1 / 12) / K, rel=1e-9)
    assert v["dark_noise_e"] * K == pytest.approx(0.40, abs=0.005)  # eq. 54: σ_d < 0.40 / K
    assert any("upper limit" in n for n in v["notes"])


def test_linearity_error_is_the_mean_absolute_relative_deviation():
    """LE (eq. 63) of a curved characteristic, against an independent weighted regression (numpy's, weights 1/y)."""
    pt = model_transfer()
    signal = pt.mean_dn - pt.dark_mean_dn
    bent = signal * (1 - 0.05 * signal / signal.max())
    v = characterize(replace(pt, mean_dn=pt.dark_mean_dn + bent)).values
    idx = np.arange(v["linearity_index_min"], v["linearity_index_max"] + 1)
    a1, a0 = np.polyfit(pt.photons[idx], bent[idx], 1, w=1.0 / bent[idx])
    fit = a0 + a1 * pt.photons[idx]
    assert v["linearity_error_percent"] == pytest.approx(np.mean(np.abs(100 * (bent[idx] - fit) / fit)), rel=1e-8)
    assert v["linearity_deviation_max_percent"] == pytest.approx(np.max(100 * (bent[idx] - fit) / fit), rel=1e-8)
    # the 5–95 % range (§6.9): every fitted point, and only those, within it
    sat_signal = bent[v["saturation_index"]]
    assert np.all((bent[idx] >= 0.05 * sat_signal) & (bent[idx] <= 0.95 * sat_signal))


def test_linearity_fit_is_eq_59_to_61():
    h = np.array([1.0, 2.0, 4.0, 7.0])
    y = np.array([1.1, 1.9, 4.2, 6.8])
    a0, a1 = linearity_fit(h, y, np.arange(4))
    design = np.column_stack([np.ones(4), h]) / y[:, None]
    expected = np.linalg.lstsq(design, y / y, rcond=None)[0]
    assert (a0, a1) == pytest.approx(tuple(expected), rel=1e-12)


def test_variance_maximum_when_the_clip_level_is_never_reached():
    pt = model_transfer()
    v = characterize(replace(pt, saturated_fraction=None)).values
    assert v["saturation_rule"] == RULE_VARIANCE
    assert v["saturation_index"] == v["variance_max_index"]
    photons = 1.0e6 * np.linspace(0.001, 0.02, 40)
    assert v["saturation_photons"] == pytest.approx(photons[ETA * photons <= SAT_E].max())


def test_a_variance_maximum_within_the_noise_of_its_successors_is_not_saturation():
    """A sweep that stops below saturation (the first 20 points of the model camera, up to 0.63 of full well), no
    pixel at the clip level, its second-brightest variance 1 % above the brightest's: with P = 3072 pixels and one
    pair, the difference of two variance estimates has a standard error of √2 · √(2/3072) = 3.6 %, so 1 % is noise
    and the brightest point is the saturation point (a lower bound, said in a note); a 30 % drop is saturation.
    Without a pixel count the maximum is taken as it is."""
    whole = model_transfer()
    pt = replace(
        whole,
        **{name: np.asarray(getattr(whole, name))[:20] for name in PER_POINT},
        spatial=SpatialSplit.unknown(20),
        dark_spatial=SpatialSplit.unknown(20),
    )
    var = pt.temporal_var_dn2.copy()
    var[18] = 1.01 * var[19]
    noisy = replace(pt, temporal_var_dn2=var, pixels=3072)
    assert characterize(noisy).values["saturation_index"] == 19
    assert any("never reaches the clip level" in note for note in characterize(noisy).values["notes"])
    assert characterize(replace(noisy, pixels=0)).values["saturation_index"] == 18
    dropped = var.copy()
    dropped[19] = 0.7 * dropped[18]
    assert characterize(replace(noisy, temporal_var_dn2=dropped)).values["saturation_index"] == 18


def test_saturation_where_the_reference_implementation_picks_a_point_past_it():
    """A photon transfer simulated by the EMVA 1288 reference implementation (tests/data): it reports the
    saturation at index 17, μ_e.sat = 36 624 e-, where the dark-corrected variance is negative; its camera clips at a
    15 000 e- full well. uwlab takes the variance peak (index 6)."""
    table = pd.read_csv(DATA / "emva1288_reference_saturation.csv", comment="#")
    n = len(table)
    pt = PhotonTransfer(
        photons=table["photons"],
        exposure_s=table["exposure_s"],
        mean_dn=table["mean_dn"],
        temporal_var_dn2=table["temporal_var_dn2"],
        frames=np.full(n, 2.0),
        dark_mean_dn=table["dark_mean_dn"],
        dark_temporal_var_dn2=table["dark_temporal_var_dn2"],
        dark_frames=np.full(n, 2.0),
        spatial=SpatialSplit.unknown(n),
        dark_spatial=SpatialSplit.unknown(n),
        dark=DarkSeries(table["exposure_s"], table["dark_mean_dn"], table["dark_temporal_var_dn2"], np.full(n, np.nan)),
        bit_depth=12,
    )
    corrected = (table["temporal_var_dn2"] - table["dark_temporal_var_dn2"]).to_numpy()
    assert corrected[17] < 0  # the reference's pick
    v = characterize(pt).values
    assert v["saturation_index"] == int(np.argmax(table["temporal_var_dn2"])) == 6
    assert corrected[v["saturation_index"]] > 0
    assert v["saturation_e"] < 15000 < 36624
    assert v["saturation_e"] == pytest.approx(v["quantum_efficiency"] * table["photons"][6])


def test_dark_current_needs_six_exposure_times():
    pt = model_transfer(n=40, dark_exposures=())
    short = replace(pt, dark=pt.dark.select(np.arange(len(pt.dark)) < 5))
    v = characterize(short).values
    assert v["dark_current_e_per_s"] is None and v["dark_current_exposures"] == 5
    assert any("at least 6" in n for n in v["notes"])


def test_dark_current_per_temperature():
    """§7.2: each recorded temperature's dark series gives its own dark current; the sweep's own temperature is
    the one reported."""
    pt = model_transfer(temperature=25.0)
    hot_t = np.linspace(0.1, 0.6, 6)
    hot = DarkSeries(
        hot_t, OFFSET + K * 4 * DARK_E_S * hot_t, K**2 * (SIGMA_D**2 + 4 * DARK_E_S * hot_t) + 1 / 12, np.full(6, 45.0)
    )
    series = pt.dark
    both = DarkSeries(
        np.r_[series.exposure_s, hot.exposure_s],
        np.r_[series.mean_dn, hot.mean_dn],
        np.r_[series.var_dn2, hot.var_dn2],
        np.r_[series.temperature_c, hot.temperature_c],
    )
    v = characterize(replace(pt, dark=both)).values
    assert v["dark_current_e_per_s"] == pytest.approx(DARK_E_S, rel=1e-9)
    by_t = {row["temperature_c"]: row["dark_current_e_per_s"] for row in v["dark_current_by_temperature"]}
    assert by_t == pytest.approx({25.0: DARK_E_S, 45.0: 4 * DARK_E_S}, rel=1e-9)


def test_a_bent_photon_transfer_suggests_the_general_model():
    pt = model_transfer(n=60)
    signal = pt.mean_dn - pt.dark_mean_dn
    bent = signal * (1 - 0.3 * signal / signal.max())
    slope = 1 - 0.6 * signal / signal.max()
    v = characterize(
        replace(pt, mean_dn=pt.dark_mean_dn + bent, temporal_var_dn2=pt.dark_temporal_var_dn2 + K * bent * slope)
    ).values
    assert v["photon_transfer_slope_deviation"] > 0.03
    assert any("--model general" in n for n in v["notes"])


def test_too_few_points_in_the_fit_range():
    with pytest.raises(ConfigError, match="too few points in the fit range"):
        characterize(model_transfer(n=4))


def _points_frame(pt: PhotonTransfer, position="sensor") -> pd.DataFrame:
    n = len(pt.photons)
    return pd.DataFrame(
        {
            "sweep_id": "s",
            "point_index": np.arange(n),
            "kind": "exposure",
            "exposure_us": pt.exposure_s * 1e6,
            "light_on": True,
            "frames": 2,
            "bit_depth": 12,
            "mean_dn": pt.mean_dn,
            "temporal_var_dn2": pt.temporal_var_dn2,
            "dark_mean_dn": pt.dark_mean_dn,
            "dark_temporal_var_dn2": pt.dark_temporal_var_dn2,
            "dark_frames": 2,
            "gain_db": 0.0,
            "sensor_profile": "imx250m",
            "camera_id": "c0",
            "light_level": 1.0,
            "irradiance_w_m2": 0.5,
            "irradiance_position": position,
            "roi_w": 64,
            "roi_h": 64,
        }
    )


EMPTY_SPECTRA = pd.DataFrame(columns=["sweep_id", "point_index", "position", "wavelength_nm", "irradiance_w_m2_nm"])


def test_points_table_to_photons():
    pt = model_transfer()
    got = photon_transfer_from_points(_points_frame(pt), EMPTY_SPECTRA, wavelength_nm=550.0)
    expected = 0.5 * photons_per_joule(550.0) * pt.exposure_s * (3.45e-6) ** 2
    np.testing.assert_allclose(got.photons, expected, rtol=1e-12)
    with pytest.raises(ConfigError, match="--wavelength-nm"):
        photon_transfer_from_points(_points_frame(pt), EMPTY_SPECTRA)


@pytest.mark.parametrize("position", ["camera", "target", None])
def test_irradiance_not_at_the_sensor_plane_is_refused(position):
    with pytest.raises(ConfigError, match="sensor plane"):
        photon_transfer_from_points(_points_frame(model_transfer(), position), EMPTY_SPECTRA, wavelength_nm=550.0)


def test_bad_tables_name_the_problem():
    pt = model_transfer()
    frame = _points_frame(pt)
    with pytest.raises(ConfigError, match="temporal_var_dn2"):
        photon_transfer_from_points(frame.drop(columns=["temporal_var_dn2"]), EMPTY_SPECTRA, wavelength_nm=550.0)
    frame.loc[3, "dark_mean_dn"] = np.nan
    with pytest.raises(ConfigError, match="point 3"):
        photon_transfer_from_points(frame, EMPTY_SPECTRA, wavelength_nm=550.0)
