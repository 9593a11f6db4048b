"""The radiometric chain and the sensor model against closed-form cases; grid results equal scalar results."""

import numpy as np
import pytest

from uwlab.experiments.design.grid import evaluate_grid
from uwlab.model.design import build_design, evaluate, on_axis_electron_rate, stage_spectra
from uwlab.model.grid import WavelengthGrid
from uwlab.model.photometry import photon_flux, radiant_per_lumen
from uwlab.model.port import port_transmittance
from uwlab.model.sensor import load_sensor_profile, response_dn, snr
from uwlab.model.spectra import relative_spectrum
from uwlab.model.water import water_iop

H, C = 6.62607015e-34, 299792458.0


@pytest.fixture
def mono555(tmp_path):
    """A 1 nm wide line at 555 nm, where V = 1: 683.002 lm of it is exactly 1 W."""
    path = tmp_path / "line.csv"
    path.write_text("wavelength_nm,relative\n553,0\n554,0\n555,1\n556,0\n557,0\n")
    return str(path)


def clear_water(raw, spectrum):
    raw["light"]["spectrum"] = spectrum
    raw["water"]["attenuation_scale"] = 0.0
    raw["light"]["luminous_flux_lm"] = 683.002
    raw["light"]["count"] = 1
    return raw


def test_cone_irradiance_is_intensity_over_distance_squared(example_raw, mono555):
    raw = clear_water(example_raw, mono555)
    raw["light"].update(beam_half_angle_deg=30.0, distance_m=2.0, incidence_deg=0.0)
    out = evaluate(build_design(raw))
    omega = 2 * np.pi * (1 - np.cos(np.radians(30.0)))
    assert out["target_irradiance_w_m2"] == pytest.approx(1.0 / omega / 4.0, rel=1e-12)


def test_disk_model_spreads_flux_over_beam_footprint(example_raw, mono555):
    raw = clear_water(example_raw, mono555)
    raw["light"].update(beam_half_angle_deg=30.0, distance_m=2.0, beam_model="disk")
    out = evaluate(build_design(raw))
    assert out["target_irradiance_w_m2"] == pytest.approx(1.0 / (np.pi * (2.0 * np.tan(np.radians(30))) ** 2))


def test_incidence_count_and_beer_lambert(example_raw, mono555):
    raw = clear_water(example_raw, mono555)
    raw["light"].update(distance_m=1.5)
    base = evaluate(build_design(raw))["target_irradiance_w_m2"]
    raw["light"].update(incidence_deg=60.0, count=3)
    assert evaluate(build_design(raw))["target_irradiance_w_m2"] == pytest.approx(base * 3 * 0.5)
    raw["light"].update(incidence_deg=0.0, count=1)
    raw["water"].update(type="jerlov-III", attenuation_scale=1.0)
    c555 = water_iop("jerlov-III", WavelengthGrid()).c_per_m[555 - 380]
    attenuated = evaluate(build_design(raw))["target_irradiance_w_m2"]
    assert attenuated == pytest.approx(base * np.exp(-c555 * 1.5), rel=1e-9)


def test_sensor_electrons_closed_form(example_raw, mono555):
    """E_s = E_t M/π · e^(-c d_C) T_port/n² T_lens π/(4N²); μ_e = A t E_s λ η / (h c) at 555 nm."""
    raw = clear_water(example_raw, mono555)
    raw["light"].update(distance_m=1.0, beam_half_angle_deg=40.0)
    raw["target"]["reflectance"] = 0.5
    raw["lens"].update(f_number=4.0, transmittance=0.8)
    raw["operation"].update(exposure_s=0.01, altitude_m=1.0)
    design = build_design(raw)
    out = evaluate(design)
    e_t = 1.0 / (2 * np.pi * (1 - np.cos(np.radians(40.0))))
    n_w = raw["housing"]["water_index"]
    e_s = e_t * 0.5 / np.pi * port_transmittance(n_w, raw["housing"]["port_index"]) / n_w**2 * 0.8 * np.pi / 64
    assert out["target_irradiance_w_m2"] == pytest.approx(e_t, rel=1e-12)
    assert out["sensor_irradiance_w_m2"] == pytest.approx(e_s, rel=1e-12)
    sensor = load_sensor_profile("imx250m")
    eta = np.interp(555.0, sensor.qe_nm, sensor.qe["combined"])
    mu_e = (3.45e-6) ** 2 * 0.01 * e_s * 555e-9 * eta / (H * C)
    assert out["mean_electrons"] == pytest.approx(min(mu_e, sensor.saturation_e), rel=1e-9)


def test_photon_count_for_known_irradiance():
    """EMVA 1288 Release 4.0 Linear eq. (4), the standard's handy-unit form of eq. (3):
    μ_p = 50.34 · A[µm²] · t_exp[ms] · λ[µm] · E[µW/cm²]. 1 W/m² (100 µW/cm²) in a 1 nm band at 555 nm on a
    3.45 µm pixel for 1 ms: 50.34 · 11.9025 · 1 · 0.555 · 100 ≈ 33 254 photons."""
    nm = np.array([554.5, 555.5])
    mu_p = photon_flux(nm, np.ones(2)) * (3.45e-6) ** 2 * 1e-3
    assert mu_p == pytest.approx(50.34 * 3.45**2 * 1.0 * 0.555 * 100, rel=2e-4)


def test_response_clipping_and_snr():
    mu_y, sat = response_dn(np.array([0.0, 1000.0, 20000.0]), 0.35, 10.0, 10700.0, 12)
    assert mu_y.tolist() == pytest.approx([10.0, 360.0, 10.0 + 0.35 * 10700.0])
    assert sat.tolist() == [False, False, True]
    mu_y, sat = response_dn(12000.0, 0.5, 0.0, 20000.0, 12)
    assert mu_y == 4095 and sat
    # SNR → sqrt(μ_e) when shot noise dominates; → μ_e/σ_d in the dark
    assert snr(1e6, 2.0, 0.35) == pytest.approx(1e3, rel=1e-5)
    assert snr(1e-3, 2.0, 100.0) == pytest.approx(1e-3 / np.sqrt(4 + 1 / 12 / 1e4 + 1e-3))


def test_gain_and_bit_depth_scale_k(example_raw):
    raw = example_raw
    raw["operation"]["exposure_s"] = 2e-5
    low = evaluate(build_design(raw))
    raw["sensor"].update(gain_db=6.0, bit_depth=16)
    high = evaluate(build_design(raw))
    assert high["mean_electrons"] == pytest.approx(low["mean_electrons"])
    profile = load_sensor_profile("imx250m")
    dark16 = 16 * profile.dark_offset_dn
    assert high["mean_dn"] - dark16 == pytest.approx(
        16 * 10 ** (6 / 20) * profile.K_dn_per_e * low["mean_electrons"], rel=1e-9
    )


def test_stage_spectra_integrate_to_the_reported_irradiances(example_raw):
    design = build_design(example_raw)
    out = evaluate(design)
    spectra = stage_spectra(design)
    grid = design.grid
    assert grid.integrate(spectra["target_irradiance_w_m2_nm"]) == pytest.approx(out["target_irradiance_w_m2"])
    assert grid.integrate(spectra["sensor_irradiance_w_m2_nm"]) == pytest.approx(out["sensor_irradiance_w_m2"])
    photons = grid.integrate(spectra["absorbed_w_m2_nm"] * grid.m) / (H * C)
    area = design.sensor.pixel_area_m2
    assert min(photons * area * out["exposure_s"], design.sensor.saturation_e) == pytest.approx(out["mean_electrons"])


def test_image_average_tends_to_on_axis_for_narrow_field(example_raw):
    example_raw["lens"]["focal_length_mm"] = 2000.0
    example_raw["operation"]["exposure_s"] = 1e-4
    out = evaluate(build_design(example_raw))
    assert out["image_average"]["mean_electrons"] == pytest.approx(out["mean_electrons"], rel=1e-5)
    example_raw["lens"]["focal_length_mm"] = 8.0
    wide = evaluate(build_design(example_raw))
    assert wide["image_average"]["mean_electrons"] < 0.95 * wide["mean_electrons"]


def test_image_average_drops_outside_narrow_beam(example_raw):
    example_raw["lens"]["focal_length_mm"] = 8.0
    example_raw["operation"]["exposure_s"] = 1e-4
    example_raw["light"]["beam_half_angle_deg"] = 60.0
    wide = evaluate(build_design(example_raw))["image_average"]["mean_electrons"]
    example_raw["light"]["beam_half_angle_deg"] = 5.0  # beam smaller than the field
    narrow = build_design(example_raw)
    out = evaluate(narrow)
    omega = lambda b: 2 * np.pi * (1 - np.cos(np.radians(b)))  # noqa: E731
    ratio = out["image_average"]["mean_electrons"] / (wide * omega(60.0) / omega(5.0))
    assert 0.0 < ratio < 0.5


def test_grid_results_equal_scalar_results(example_raw):
    example_raw["operation"]["exposure_s"] = 1e-4
    axes = {
        "operation.altitude_m": [0.5, 1.0, 3.0],
        "lens.f_number": [1.4, 2.8, 8.0],
        "water.type": ["pure-fresh", "jerlov-3C"],
        "housing.port": ["flat", "dome"],
    }
    example_raw["housing"].update(dome_radius_mm=100.0, dome_thickness_mm=10.0)
    frame = evaluate_grid(example_raw, axes)
    assert len(frame) == 36
    for _, row in frame.sample(8, random_state=1).iterrows():
        raw = {s: dict(v) for s, v in example_raw.items()}
        raw["operation"]["altitude_m"] = row["operation.altitude_m"]
        raw["lens"]["f_number"] = row["lens.f_number"]
        raw["water"]["type"] = row["water.type"]
        raw["housing"]["port"] = row["housing.port"]
        scalar = evaluate(build_design(raw))
        for key in ("mean_electrons", "snr", "target_irradiance_w_m2", "min_f_number_for_dof"):
            assert row[key] == pytest.approx(float(scalar[key]), rel=1e-12)
        assert row["dof_m_near"] == pytest.approx(float(scalar["dof_m"]["near"]), rel=1e-12)
        assert row["image_average_mean_dn"] == pytest.approx(float(scalar["image_average"]["mean_dn"]), rel=1e-12)


def test_operation_hand_case(example_raw):
    example_raw["operation"].update(altitude_m=2.0, speed_m_s=1.0, overlap=0.5, max_blur_px=2.0, motion_axis="y")
    example_raw["lens"]["focal_length_mm"] = 10.0
    out = evaluate(build_design(example_raw))
    fov_y = 2048 * 3.45e-6 / (0.010 * 1.333) * 2.0  # footprint = altitude · size / f_uw
    assert out["fov_m"]["y"] == pytest.approx(fov_y, rel=1e-12)
    assert out["min_framerate_hz"] == pytest.approx(1.0 / (fov_y * 0.5), rel=1e-12)
    assert out["max_exposure_s"] == pytest.approx(2.0 * fov_y / (1.0 * 2048), rel=1e-12)


def test_dome_port_keeps_fov_and_reports_virtual_image(example_raw):
    example_raw["housing"].update(port="dome", dome_radius_mm=100.0, dome_thickness_mm=10.0)
    out = evaluate(build_design(example_raw))
    assert out["effective_focal_length_mm"] == pytest.approx(30.0)
    assert 0.1 < out["dome_virtual_image_m"] < 1.333 * 0.1 / 0.333 * 1.01


@pytest.mark.parametrize(
    "override",
    [
        {},
        {"housing": {"port": "dome", "dome_radius_mm": 100.0, "dome_thickness_mm": 10.0}},
        {"light": {"beam_model": "disk", "count": 3, "incidence_deg": 20.0}},
        {"water": {"type": "jerlov-5C", "attenuation_scale": 1.7}, "target": {"reflectance": "sand"}},
    ],
)
def test_light_budget_adds_up_to_source_photons_over_sensor_electrons(example_raw, override):
    """Σ stops = log₂(photons emitted per second / electrons per second over the sensor at the on-axis rate)."""
    for section, values in override.items():
        example_raw[section].update(values)
    design = build_design(example_raw)
    stops = evaluate(design)["light_budget_stops"]
    grid = design.grid
    spectrum = relative_spectrum(design["light.spectrum"], grid)
    photons_per_lm = grid.integrate(radiant_per_lumen(spectrum, grid) * grid.m) / (H * C)
    emitted = design["light.count"] * design["light.luminous_flux_lm"] * photons_per_lm
    collected = float(on_axis_electron_rate(design)) * np.prod(design.sensor.resolution_px)
    assert sum(stops.values()) == pytest.approx(np.log2(emitted / collected), rel=1e-9)


def test_light_budget_stages_closed_forms(example_raw, mono555):
    raw = clear_water(example_raw, mono555)
    raw["target"]["reflectance"] = 0.5
    raw["lens"].update(f_number=4.0, transmittance=0.8, focal_length_mm=25.0)
    raw["operation"]["altitude_m"] = 2.0
    design = build_design(raw)
    stops = evaluate(design)["light_budget_stops"]
    n_w = raw["housing"]["water_index"]
    eta = np.interp(555.0, design.sensor.qe_nm, design.sensor.qe["combined"])
    assert stops["water_to_target"] == pytest.approx(0.0, abs=1e-12)
    assert stops["water_to_camera"] == pytest.approx(0.0, abs=1e-12)
    assert stops["reflectance"] == pytest.approx(1.0, rel=1e-12)
    assert stops["lens_transmittance"] == pytest.approx(-np.log2(0.8), rel=1e-12)
    assert stops["port"] == pytest.approx(-np.log2(port_transmittance(n_w, raw["housing"]["port_index"])), rel=1e-12)
    assert stops["aperture"] == pytest.approx(-np.log2(0.025**2 / (4 * 16 * 4.0)), rel=1e-12)
    assert stops["quantum_efficiency"] == pytest.approx(-np.log2(eta), rel=1e-9)
    raw["water"].update(type="jerlov-III", attenuation_scale=1.0)
    c555 = water_iop("jerlov-III", WavelengthGrid()).c_per_m[555 - 380]
    murky = evaluate(build_design(raw))["light_budget_stops"]
    assert murky["water_to_camera"] == pytest.approx(c555 * 2.0 / np.log(2), rel=1e-9)
