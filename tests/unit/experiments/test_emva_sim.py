"""A characterisation of the simulated camera recovers its ground truth, which the analysis never sees: K, η, σ_d,
saturation, dark current (and its temperature dependence), DSNU, PRNU (also under strong vignetting), the linearity
error of a known non-linearity, and the nonuniformity images (accuracy stated in docs/emva.md)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from uwlab.sim.devices.camera import SimTruth
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.emva.analysis import characterize
from uwlab.experiments.emva.from_dataset import IrradianceOverride, photon_transfer_from_points
from uwlab.experiments.frames.nonuniformity import white_noise_gain
from uwlab.experiments.emva.simulate import DirectBench, sim_truth_of, simulate_photon_transfer
from uwlab.model.sensor import load_sensor_profile

RATE_E_S = 1.07e5  # full well (10700 e-) at 100 ms
ETA = 0.6
DARK_E_S, DSNU, PRNU = 200.0, 1.5, 1.0


def truth(**changes) -> SimTruth:
    return SimTruth.from_sensor_profile(
        load_sensor_profile("imx250m"),
        resolution_px=(96, 96),
        dark_current_e_per_s=DARK_E_S,
        dsnu_e=DSNU,
        prnu_percent=PRNU,
        **changes,
    )


def sim_exposures_us():
    """50 about equally spaced exposures to 115 % of the full well."""
    return np.linspace(2e3, 115e3, 50)


@pytest.fixture(scope="module")
def sim_dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("emva") / "ds"
    simulate_photon_transfer(
        root,
        truth(),
        rate_e_per_s=RATE_E_S,
        quantum_efficiency=ETA,
        exposures_us=sim_exposures_us(),
        frames=2,
        seed=7,
        dark_exposures_us=np.linspace(0.2e6, 1.2e6, 6),
    )
    return root


@pytest.fixture(scope="module")
def result(sim_dataset):
    ds = Dataset.open(sim_dataset)
    return characterize(photon_transfer_from_points(ds.points(), ds.spectra())).values


def test_recovers_ground_truth(sim_dataset, result):
    t = sim_truth_of(sim_dataset)
    assert result["K_dn_per_e"] == pytest.approx(t["K_dn_per_e"], rel=0.01)
    assert result["quantum_efficiency"] == pytest.approx(t["quantum_efficiency"], rel=0.01)
    # σ_d at the shortest exposure (2 ms) includes that exposure's dark-current shot noise (eq. 30)
    assert result["dark_noise_e"] == pytest.approx(math.sqrt(t["dark_noise_e"] ** 2 + DARK_E_S * 2e-3), rel=0.03)
    # saturation (§6.6): below the full well, where clipping starts to bite
    assert 0.93 * t["saturation_e"] < result["saturation_e"] < t["saturation_e"]
    assert result["dark_current_e_per_s"] == pytest.approx(t["dark_current_e_per_s"], rel=0.02)
    assert result["dark_current_var_e_per_s"] == pytest.approx(t["dark_current_e_per_s"], rel=0.05)
    # the highpass keeps 98.85 % of a white pattern's variance (§8.1); from the 2-frame point at 50 % and 78 × 78
    # highpassed pixels the DSNU has a statistical spread of ~2.6 % (its variance sits on σ²_y.dark / 2, eq. 36)
    gain = math.sqrt(white_noise_gain())
    assert result["dsnu_e"] == pytest.approx(DSNU * gain, rel=0.1)
    assert result["prnu_percent"] == pytest.approx(PRNU * gain, rel=0.1)
    assert abs(result["dsnu_row_e"] or 0) < 0.3 and abs(result["dsnu_col_e"] or 0) < 0.3
    assert result["linearity_error_percent"] < 0.1
    assert 0 < result["photon_transfer_slope_deviation"] - result["photon_transfer_slope_noise"] < 0.03
    assert not any("--model general" in n for n in result["notes"])
    assert result["saturation_rule"].startswith("0.2 %")


def test_uncertainties_cover_the_truth(sim_dataset, result):
    t = sim_truth_of(sim_dataset)
    for key in ("K_dn_per_e", "quantum_efficiency", "dark_current_e_per_s"):
        assert result[f"{key}_std"] > 0
        assert abs(result[key] - t[key]) < 5 * result[f"{key}_std"] + 0.005 * t[key]


def test_irradiance_override_matches_the_spectrometer(sim_dataset, result):
    ds = Dataset.open(sim_dataset)
    row = ds.points().iloc[0]
    spectrum = ds.spectra().query("point_index == 0 and sweep_id == 'sim-photon-transfer'")
    override = IrradianceOverride(
        spectrum_nm=spectrum["wavelength_nm"].to_numpy(), spectrum_w_m2_nm=spectrum["irradiance_w_m2_nm"].to_numpy()
    )
    pt = photon_transfer_from_points(ds.points(), ds.spectra(), override=override)
    assert characterize(pt).values["quantum_efficiency"] == pytest.approx(result["quantum_efficiency"], rel=1e-9)
    mono = IrradianceOverride(irradiance_w_m2=float(row["irradiance_w_m2"]), wavelength_nm=525.0)
    pt = photon_transfer_from_points(ds.points(), ds.spectra(), override=mono)
    assert characterize(pt).values["quantum_efficiency"] == pytest.approx(result["quantum_efficiency"], rel=0.005)


@pytest.fixture(scope="module")
def stack_result():
    bench = DirectBench(truth(), RATE_E_S, ETA, seed=11)
    return characterize(
        bench.photon_transfer(
            sim_exposures_us(), dark_exposures_us=np.linspace(0.2e6, 1.2e6, 6), stack_exposure_us=50e3, stack_frames=32
        )
    )


def test_nonuniformity_stacks(stack_result):
    """DSNU and PRNU from 32-frame stacks (§8.2–8.3), and the images' spectrograms and histograms (§8.6, §8.8)."""
    v, images = stack_result.values, stack_result.images
    gain = math.sqrt(white_noise_gain())
    assert v["nonuniformity_source"].startswith("stacks of 32")
    assert v["dsnu_e"] == pytest.approx(DSNU * gain, rel=0.04)
    assert v["prnu_percent"] == pytest.approx(PRNU * gain, rel=0.04)
    assert v["dsnu_pixel_e"] == pytest.approx(v["dsnu_e"], rel=0.05)
    # white patterns: flat spectrograms at the DSNU (in DN) and PRNU (in %) levels, plus the residual temporal noise
    k = v["K_dn_per_e"]
    dsnu_level = np.sqrt(
        (DSNU * k) ** 2 * white_noise_gain() + v["spatial_variances"]["dark_stack_var"] / 32 * white_noise_gain()
    )
    assert np.median(images.dsnu_spectrograms["horizontal"][1][5:]) == pytest.approx(dsnu_level, rel=0.1)
    assert images.dsnu_histograms["log"].counts.sum() == 78 * 78
    assert images.prnu_profiles["horizontal"]["mean"].size == 96


def test_vignetting_does_not_inflate_prnu():
    """A 35 % smooth falloff to the corners (cos⁴-like) leaves PRNU₁₂₈₈ at the sensor's 1 % (§8.1 highpass), where
    the unfiltered spatial variance of the same images is dominated by the falloff."""
    width, height = 96, 96
    y, x = np.mgrid[0:height, 0:width]
    r2 = ((x - width / 2) ** 2 + (y - height / 2) ** 2) / ((width / 2) ** 2 + (height / 2) ** 2)
    falloff = (1 - 0.35 * r2).astype(np.float32)
    bench = DirectBench(truth(), RATE_E_S, ETA, rate_map=lambda shape: RATE_E_S * falloff, seed=13)
    pt = bench.photon_transfer(
        sim_exposures_us(), dark_exposures_us=np.linspace(0.2e6, 1.2e6, 6), stack_exposure_us=50e3, stack_frames=32
    )
    v = characterize(pt).values
    assert v["prnu_percent"] == pytest.approx(PRNU * math.sqrt(white_noise_gain()), rel=0.06)
    s = pt.stack
    excess = s.bright.spatial_var_dn2 - s.dark.spatial_var_dn2
    unfiltered = 100 * math.sqrt(excess) / (s.bright.mean_dn - s.dark.mean_dn)
    assert unfiltered > 8 * PRNU


def test_dark_current_against_temperature():
    """§7.2 with the Release 3.1 doubling law as the simulated sensor's truth (doubling every 7 °C)."""
    t = truth(dark_current_doubling_c=7.0, temperature_c=30.0)
    bench = DirectBench(t, RATE_E_S, ETA, seed=5)
    pt = bench.photon_transfer(
        sim_exposures_us()[::2], dark_exposures_us=np.linspace(0.2e6, 1.2e6, 6), dark_temperatures_c=(37.0, 44.0)
    )
    rows = characterize(pt).values["dark_current_by_temperature"]
    assert [r["temperature_c"] for r in rows] == [30.0, 37.0, 44.0]
    for row in rows:
        expected = t.at_temperature(row["temperature_c"]).dark_current_e_per_s
        assert row["dark_current_e_per_s"] == pytest.approx(expected, rel=0.03)
    assert rows[2]["dark_current_e_per_s"] / rows[0]["dark_current_e_per_s"] == pytest.approx(4.0, rel=0.04)


def test_linearity_error_of_a_known_non_linearity():
    """The simulated sensor compresses its signal by β e²/e_sat; LE (eq. 63) of the measurement matches LE of the
    noise-free characteristic μ_y − μ_y.dark = K (μ_e − β μ_e²/e_sat) at the same exposures, computed here by an
    independent weighted regression."""
    beta = 0.02
    t = truth(nonlinearity=beta)
    bench = DirectBench(t, RATE_E_S, ETA, seed=17)
    v = characterize(bench.photon_transfer(sim_exposures_us(), dark_exposures_us=np.linspace(0.2e6, 1.2e6, 6))).values
    photons = RATE_E_S * sim_exposures_us() * 1e-6 / ETA
    idx = np.arange(v["linearity_index_min"], v["linearity_index_max"] + 1)
    mu_e = ETA * photons[idx]
    dark_e = DARK_E_S * sim_exposures_us()[idx] * 1e-6  # the dark electrons are compressed with the signal
    y = t.K_dn_per_e * (t.compressed_e(mu_e + dark_e) - t.compressed_e(dark_e))
    a1, a0 = np.polyfit(photons[idx], y, 1, w=1.0 / y)
    fit = a0 + a1 * photons[idx]
    expected = float(np.mean(np.abs(100 * (y - fit) / fit)))
    assert expected > 0.2
    assert v["linearity_error_percent"] == pytest.approx(expected, rel=0.1)


def test_the_linear_model_refuses_a_strongly_non_linear_camera():
    bench = DirectBench(truth(nonlinearity=0.25), RATE_E_S, ETA, seed=19)
    v = characterize(bench.photon_transfer(sim_exposures_us(), dark_exposures_us=np.linspace(0.2e6, 1.2e6, 6))).values
    assert v["photon_transfer_slope_deviation"] > 0.1
    assert any("--model general" in n for n in v["notes"])


def test_stable_means_and_a_stability_curve(stack_result):
    c = stack_result.curves
    assert np.all(np.isfinite(c["mean_diff_dn"]))
    assert np.abs(c["mean_diff_dn"]).max() < 1.0  # the simulated light does not flicker


def test_sim_truth_records_nonlinearity_and_doubling():
    t = truth(nonlinearity=0.1, dark_current_doubling_c=8.0)
    assert replace(t, temperature_c=48.0).dark_current_e_per_s == DARK_E_S
    assert t.at_temperature(48.0).dark_current_e_per_s == pytest.approx(2 * DARK_E_S)
    assert t.compressed_e(t.saturation_e) == pytest.approx(0.9 * t.saturation_e)


def test_a_profile_refuses_an_implausible_response_curve_in_one_line(result):
    """The response curve is fitted as plain numbers and checked as the profile's `ResponseCurve` where the profile
    is written: a measured one passes, a coefficient beyond its limit is a one-line error naming it."""
    from uwlab.errors import ConfigError
    from uwlab.experiments.emva.profile import profile_documents

    kwargs = {"name": "cam", "width_px": 96, "height_px": 96, "exposure_range_us": (10, 1e6), "pixel_size_um": 3.45}
    assert result["response"] is not None and abs(result["response"]["a"]) < 0.05
    assert "[response]" in profile_documents(result, **kwargs)[0]
    bad = {**result, "response": {**result["response"], "a": 3.0}}
    with pytest.raises(ConfigError, match=r"response\.a"):
        profile_documents(bad, **kwargs)
