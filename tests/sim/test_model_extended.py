"""The extended chain ([model] kind = "extended") against closed forms, brute-force quadrature and the paper's chain."""

import copy

import numpy as np
import pytest

from uwlab.errors import ConfigError
from uwlab.model import extended
from uwlab.model.design import build_design, evaluate, on_axis_electron_rate, paper, spectral_weights
from uwlab.model.optics import lens_irradiance_factor
from uwlab.model.photometry import photons_per_joule
from uwlab.model.port import port_transmittance
from uwlab.model.scattering import fournier_forand_phase, pure_water_phase
from uwlab.model.sensor import snr


@pytest.fixture
def clear(tmp_path):
    """A water that absorbs but does not scatter (b = 0): the veiling light vanishes."""
    path = tmp_path / "clear.csv"
    path.write_text("wavelength_nm,a_per_m,b_per_m\n380,0.02,0\n780,0.5,0\n")
    return str(path)


def on_axis_light(raw, water, distance_m, beam_model="cone"):
    """One light on the optical axis at `distance_m` from the target, aimed along the axis (in front of the camera,
    which looks through it: the clear water makes that harmless)."""
    raw = copy.deepcopy(raw)
    raw["water"] = {"type": water}
    raw["light"].update(
        beam_half_angle_deg=35.0, beam_model=beam_model, distance_m=distance_m, incidence_deg=0.0, count=1
    )
    raw["model"] = {"kind": "extended"}
    raw["lights"] = [{"position_m": [0.0, 0.0, raw["operation"]["altitude_m"] - distance_m]}]
    return raw


@pytest.mark.parametrize("beam_model", ["cone", "disk"])
def test_one_light_on_axis_reduces_to_the_paper(example_raw, clear, beam_model):
    raw = on_axis_light(example_raw, clear, distance_m=0.6, beam_model=beam_model)
    d = build_design(raw)
    ext, pap = evaluate(d), evaluate(paper(d))
    assert ext["veil_electrons"] == 0.0
    for key in ("target_irradiance_w_m2", "sensor_irradiance_w_m2", "mean_electrons", "snr"):
        assert ext[key] == pytest.approx(pap[key], rel=1e-8), key


def test_paper_kind_ignores_every_extension_bit_for_bit(example_raw):
    plain = build_design(example_raw)
    raw = copy.deepcopy(example_raw)
    raw["lights"] = [{"position_m": [0.1, -0.2, 0.0], "luminous_flux_lm": 1000.0}]
    raw["light"].update(separation_m=0.3, aim="parallel")
    raw["target"].update(board_size_m=[0.2, 0.2], surround_reflectance=0.05)
    raw["lens"]["mechanical_vignetting"] = 0.4
    dressed = build_design(raw)
    assert_same_bits(evaluate(plain), evaluate(dressed))


def assert_same_bits(a, b, key="outputs"):
    if isinstance(a, dict):
        assert a.keys() == b.keys(), key
        for k in a:
            assert_same_bits(a[k], b[k], f"{key}.{k}")
    elif a is None:
        assert b is None, key
    else:
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes(), key


def test_veiling_light_vanishes_with_scattering_and_grows_with_it(example_raw):
    raw = copy.deepcopy(example_raw)
    raw["model"] = {"kind": "extended"}
    raw["lights"] = [{"position_m": [0.0, -0.15, 0.0]}]
    raw["water"] = {"type": "pure-fresh", "attenuation_scale": 1.0}
    veil = []
    for b in (0.0, 0.01, 0.02):
        raw["water"]["particle_scattering_per_m"] = b
        veil.append(float(evaluate(build_design(raw))["veil_electrons"]))
    clear_veil = veil[0]  # pure water's own (Morel) scattering
    assert 0 < clear_veil < veil[1] < veil[2]
    assert (veil[2] - clear_veil) == pytest.approx(2 * (veil[1] - clear_veil), rel=0.02)  # linear in b as b → 0
    raw["water"]["attenuation_scale"] = 0.0  # no water at all: no scattering
    raw["water"]["particle_scattering_per_m"] = 0.0
    assert float(evaluate(build_design(raw))["veil_electrons"]) == 0.0


def test_a_water_types_excess_over_pure_water_scatters_as_particles(example_raw, tmp_path):
    """A tabulated water whose b exceeds pure water's by a flat X scatters that excess with the particles' phase
    function: the same veiling light as pure water's b plus added particles of b_p = X at every wavelength, the
    absorption and the beam attenuation being equal. Were the excess scattered as pure water (which back-scatters
    half its light, particles 1.8 %), the veil would be many times larger."""
    from uwlab.model.water import pure_water_scattering

    nm = np.arange(380.0, 781.0, 1.0)
    b_w = pure_water_scattering(nm)
    excess = 0.3

    def water(name, b):
        path = tmp_path / name
        rows = "\n".join(f"{w},{0.05 + excess},{v}" for w, v in zip(nm, b, strict=True))
        path.write_text("wavelength_nm,a_per_m,b_per_m\n" + rows + "\n")
        return str(path)

    raw = copy.deepcopy(example_raw)
    raw["model"] = {"kind": "extended"}
    raw["lights"] = [{"position_m": [0.0, -0.3, 0.0]}]
    raw["water"] = {"type": water("turbid.csv", b_w + excess)}
    tabulated = evaluate(build_design(raw))
    raw["water"] = {
        "type": water("added.csv", b_w),
        "particle_scattering_per_m": excess,
        "particle_scattering_exponent": 0.0,
    }
    added = evaluate(build_design(raw))
    assert tabulated["veil_electrons"] > 0
    assert tabulated["veil_electrons"] == pytest.approx(added["veil_electrons"], rel=1e-9)
    assert tabulated["mean_electrons"] == pytest.approx(added["mean_electrons"], rel=1e-9)


def test_veiling_integral_against_brute_force_quadrature(example_raw):
    """The on-axis pixel's path radiance, by the trapezoidal rule on 20 001 points and the wavelength sum, written
    out independently of the chain: β(θ) E⊥ e^(−c (r + s)) along the ray."""
    raw = copy.deepcopy(example_raw)
    raw["model"] = {"kind": "extended"}
    raw["water"] = {"type": "pure-fresh", "particle_scattering_per_m": 1.0}
    raw["light"].update(beam_model="cos-power", beam_half_angle_deg=30.0)
    raw["lights"] = [{"position_m": [0.0, -0.1, 0.0]}]
    raw["operation"]["altitude_m"] = 1.0
    d = build_design(raw)
    w = spectral_weights(d)
    chain = extended.Chain(d, w)
    lens_t = d["lens.transmittance"]
    _, veil = chain.pixel_rates(np.zeros(1), np.zeros(1), port_transmittance(1.333, 1.49), lens_t)

    s = np.linspace(0.0, 1.0, 20001)
    v = np.stack([0 * s, 0.1 + 0 * s, s], axis=1)
    r = np.linalg.norm(v, axis=1)
    m = -np.log(2) / np.log(np.cos(np.radians(30.0)))
    kappa = (m + 1) / (2 * np.pi) * (s / r) ** m
    cos_theta = -s / r
    flux = d["light.luminous_flux_lm"]
    beta = pure_water_phase(cos_theta)[:, None] * w.b_water + fournier_forand_phase(cos_theta)[:, None] * w.b_particles
    radiance = np.trapezoid(
        flux * kappa[:, None] / r[:, None] ** 2 * beta * w.s_per_lm * np.exp(-np.outer(r + s, w.c)), s, axis=0
    )
    electrons = np.sum(radiance * w.qe * photons_per_joule(d.grid.nm) * d.grid.w_nm * w.lens_transmittance)
    expected = (
        electrons
        * d.sensor.pixel_area_m2
        * port_transmittance(1.333, 1.49)
        / 1.333**2
        * lens_t
        * lens_irradiance_factor(d["lens.f_number"])
    )
    assert float(veil[0]) == pytest.approx(expected, rel=2e-3)


@pytest.mark.parametrize(
    "model,in_air", [("cone", False), ("disk", False), ("cos-power", False), ("cone", True), ("cos-power", True)]
)
def test_beam_profiles_carry_the_whole_flux(model, in_air):
    """∫ κ dω over the sphere: 1 (flux conserved, also through a flat port by étendue); the disk's 'solid angle'
    π tan²β is the small-angle one, so its integral exceeds 1 by a known amount."""
    beam = extended.Beam(model, np.radians(30.0), in_air)
    psi = np.linspace(0, np.pi, 400001)
    total = np.trapezoid(2 * np.pi * np.sin(psi) * beam.kappa(np.cos(psi), 1.333), psi)
    if model == "disk":
        assert total == pytest.approx(2 * (1 - np.cos(np.radians(30.0))) / np.tan(np.radians(30.0)) ** 2, rel=1e-3)
    else:
        assert total == pytest.approx(1.0, rel=1e-3)


def test_lights_add_up_and_separation_is_a_grid_axis(example_raw):
    raw = copy.deepcopy(example_raw)
    raw["model"] = {"kind": "extended"}
    raw["water"] = {"type": "pure-fresh", "particle_scattering_per_m": 2.0}
    raw["lights"] = [{"position_m": [0.0, -0.2, 0.0]}]
    one = evaluate(build_design(raw))
    raw["lights"] = [
        {"position_m": [0.0, -0.2, 0.0]},
        {"position_m": [0.0, -0.2, 0.0], "luminous_flux_lm": 2 * 25000.0},
    ]
    three = evaluate(build_design(raw))
    assert three["target_irradiance_w_m2"] == pytest.approx(3 * one["target_irradiance_w_m2"], rel=1e-12)
    assert three["veil_electrons"] == pytest.approx(3 * one["veil_electrons"], rel=1e-9)

    del raw["lights"]
    raw["light"].update(separation_m=np.array([0.05, 0.1, 0.2, 0.4]), aim="parallel", count=2)
    raw["operation"]["exposure_s"] = 2e-5
    raw["light"]["luminous_flux_lm"] = 1000.0  # far from saturation
    out = evaluate(build_design(raw))
    veil = np.asarray(out["veil_electrons"])
    assert veil.shape == (4,) and np.all(np.diff(veil) < 0)  # light–camera separation cuts the veil
    single = copy.deepcopy(raw)
    single["light"]["separation_m"] = 0.2
    assert float(evaluate(build_design(single))["veil_electrons"]) == pytest.approx(veil[2], rel=1e-12)


def test_mechanical_vignetting_darkens_the_corner_only(example_raw):
    raw = copy.deepcopy(example_raw)
    raw["model"] = {"kind": "extended"}
    raw["lights"] = [{"position_m": [0.0, -0.1, 0.0]}]
    d0 = build_design(raw)
    raw["lens"]["mechanical_vignetting"] = 0.3
    d1 = build_design(raw)
    corner = np.array(d0.sensor.size_m) / 2
    rates = [
        extended.Chain(d, spectral_weights(d)).pixel_rates(
            np.array([0.0, corner[0]]), np.array([0.0, corner[1]]), 0.95, 0.9
        )
        for d in (d0, d1)
    ]
    assert rates[1][0][0] == rates[0][0][0]
    assert rates[1][0][1] / rates[0][0][1] == pytest.approx(0.7, rel=1e-12)
    assert evaluate(d1)["image_average"]["mean_electrons"] < evaluate(d0)["image_average"]["mean_electrons"]


def test_bare_sensor_sees_its_board_and_its_surround(example_raw):
    """A bare sensor (f/0.5) integrates its hemisphere: a board filling the view gives more than a small board on a
    black surround, and the surround's reflectance adds its share."""
    raw = copy.deepcopy(example_raw)
    raw["model"] = {"kind": "extended"}
    raw["lights"] = [{"position_m": [0.0, -0.1, 0.0]}]
    raw["lens"].update(f_number=0.5, transmittance=1.0)
    raw["target"]["reflectance"] = 0.5
    full = on_axis_electron_rate(build_design(raw))
    raw["target"].update(board_size_m=[0.3, 0.3], surround_reflectance=0.0)
    small = on_axis_electron_rate(build_design(raw))
    raw["target"]["surround_reflectance"] = 0.5
    assert on_axis_electron_rate(build_design(raw)) == pytest.approx(full, rel=1e-12)
    assert 0 < small < 0.6 * full


def test_veil_adds_shot_noise_to_the_snr():
    assert snr(1000.0, 2.0, 0.5, veil_e=300.0) == pytest.approx(1000.0 / np.sqrt(4.0 + 1 / 12 / 0.25 + 1300.0))
    assert snr(1000.0, 2.0, 0.5) == snr(1000.0, 2.0, 0.5, veil_e=None)


def test_extended_placement_errors(example_raw):
    raw = copy.deepcopy(example_raw)
    raw["model"] = {"kind": "extended"}
    raw["lights"] = [{"position_m": [0.0, 0.0, 0.0], "aim_m": [0.0, 0.0, 0.0]}]
    with pytest.raises(ConfigError, match=r"lights\[0\].aim_m"):
        evaluate(build_design(raw))
    raw["lights"] = [{"position_m": [0.0, 0.0, 5000.0]}]
    with pytest.raises(ConfigError, match="lights"):
        build_design(raw)
    del raw["lights"]  # the paper's placement puts the light at the camera: unbounded veil in scattering water
    with pytest.raises(ConfigError, match="light.distance_m.*axis"):
        evaluate(build_design(raw))
