"""The on-axis image-formation chain, evaluated with numpy broadcasting: geometry, paths and rates.

On-axis chain (Billings, Iscar & Johnson-Roberson, "Parametric Design of Underwater Optical Systems", with the
corrections listed in the README): light → water → Lambertian target → water → port → lens → sensor.

1. Φe(λ) = count · Φv · S(λ) / (K_m ∫ S V dλ)                       [W/nm]   (uwlab.model.photometry)
2. cone: E_t = Φe / Ω · cos θi / d_L² · e^(−c d_L), Ω = 2π(1 − cos β);
   disk (the original tool): E_t = Φe / (π (d_L tan β)²) · e^(−c d_L)    [W/m²/nm]
3. c(λ) = (a + b) · attenuation_scale                                         (uwlab.model.water)
4. L_t = E_t M / π;  5. L_w = L_t e^(−c d_C);  6. L_a = L_w T_port / n_w²    [W/m²/sr/nm]
7. E_s = L_a T_lens π / (4 N²) cos⁴α                                          (uwlab.model.optics)
8. μ_e = A t / (h c) ∫ E_s λ η dλ;  μ_y = μ_y,dark + K μ_e (clipped)          (uwlab.model.sensor)
"""

from __future__ import annotations

import numpy as np

from uwlab.model import extended, optics
from uwlab.model import port as port_model
from uwlab.model.design import Design
from uwlab.model.weights import SpectralWeights, broadband_factor, path_integrals, spectral_weights


def beam_half_angle_rad(d: Design):
    """Beam half-angle in water [rad]; one given in air behind a flat light port is refracted (Snell)."""
    if d["light.beam_half_angle_deg"] is not None:
        return np.radians(d["light.beam_half_angle_deg"])
    return np.arcsin(np.sin(np.radians(d["light.beam_half_angle_in_air_deg"])) / d["housing.water_index"])


def irradiance_geometry(d: Design, beta, cos_incidence):
    """Target irradiance per unit spectral radiant flux without attenuation [1/m²] (steps 2 of the chain)."""
    count = d["light.count"]
    d_l = light_distance_m(d)
    if paper_beam_model(d) == "cone":
        return count * cos_incidence / (2 * np.pi * (1 - np.cos(beta)) * d_l**2)
    return count / (np.pi * (d_l * np.tan(beta)) ** 2)


def paper_beam_model(d: Design) -> str:
    """The paper chain's beam: "disk", or "cone" (a cos-power beam, an extended-model profile, counts as a cone of
    its half-angle)."""
    return "disk" if d["light.beam_model"] == "disk" else "cone"


def light_distance_m(d: Design):
    """Light → target distance [m]: `light.distance_m`, by default the altitude."""
    value = d["light.distance_m"]
    return d["operation.altitude_m"] if value is None else value


def housing_transmittance(d: Design):
    """The camera port's transmittance: the configured number, or the Fresnel value at normal incidence."""
    value = d["housing.port_transmittance"]
    if isinstance(value, str):
        return port_model.port_transmittance(d["housing.water_index"], d["housing.port_index"])
    return value


def _radiance_to_sensor_factor(d: Design, weights: SpectralWeights):
    """Broadband factors from target irradiance to sensor irradiance: M/π · T_port/n_w² · T_lens · π/(4N²)."""
    m = broadband_factor(d, "target.reflectance")
    t = broadband_factor(d, "lens.transmittance")
    return (
        (m / np.pi)
        * housing_transmittance(d)
        / d["housing.water_index"] ** 2
        * t
        * optics.lens_irradiance_factor(d["lens.f_number"])
    )


def effective_focal_length_m(d: Design):
    """Focal length seen from the water [m]: n_w f behind a flat port, f behind a centred dome."""
    f = d["lens.focal_length_mm"] * 1e-3
    return f * d["housing.water_index"] if d["housing.port"] == "flat" else f * np.ones_like(d["housing.water_index"])


def field_terms(d: Design, r_m):
    """(angular weight, path secant) of pixels at image radius r_m (trailing axis): cos⁴α_air · [α_w ≤ β] ·
    cos³α_w (cone model; 1 for the disk) and 1/cos α_w, broadcast against the design's arrays."""
    beta = beam_half_angle_rad(d)
    f = np.asarray(d["lens.focal_length_mm"] * 1e-3, float)[..., None]
    tan_air = np.asarray(r_m, float) / f
    tan_w = tan_air / np.asarray(d["housing.water_index"])[..., None] if d["housing.port"] == "flat" else tan_air
    cos_air = 1 / np.sqrt(1 + tan_air**2)
    cos_w = 1 / np.sqrt(1 + tan_w**2)
    in_beam = np.arctan(tan_w) <= np.asarray(beta)[..., None]
    return cos_air**4 * in_beam * (cos_w**3 if paper_beam_model(d) == "cone" else 1.0), 1 / cos_w


def attenuating_path_m(d: Design):
    """Attenuating path of the on-axis pixel, light → target → camera: scale · (d_L + d_C) [m]."""
    return np.asarray(d["water.attenuation_scale"]) * (np.asarray(light_distance_m(d)) + d["operation.altitude_m"])


def image_prefactor(d: Design, weights: SpectralWeights):
    """Electron rate per unit (angular weight × spectral integral) of the off-axis pixels: flux, beam
    concentration without incidence, broadband factors to the sensor, pixel area."""
    beta = beam_half_angle_rad(d)
    return (
        d["light.luminous_flux_lm"]
        * irradiance_geometry(d, beta, 1.0)
        * _radiance_to_sensor_factor(d, weights)
        * d.sensor.pixel_area_m2
    )


def electron_rate_at_radius(d: Design, r_m, weights: SpectralWeights | None = None):
    """Electron rate [e⁻/s] of pixels at image radius r_m (any shape, trailing axis broadcast against the
    design's arrays) under the image-average geometry of the module docstring: light beside the camera,
    target plane perpendicular to the axis at d_C, cos⁴ lens falloff, beam cut-off at α_w > β. Summed over the
    wavelength grid (`path_integrals`): the reference for the image average."""
    weights = spectral_weights(d) if weights is None else weights
    angular, secant = field_terms(d, r_m)
    path = attenuating_path_m(d)[..., None] * secant
    return np.asarray(image_prefactor(d, weights))[..., None] * angular * path_integrals(weights, path)[..., 2]


def on_axis_quantities(d: Design, weights: SpectralWeights):
    """(target irradiance [W/m²], sensor irradiance [W/m²], electron rate [e⁻/s]) on the optical axis."""
    beta = beam_half_angle_rad(d)
    geometry = d["light.luminous_flux_lm"] * irradiance_geometry(d, beta, np.cos(np.radians(d["light.incidence_deg"])))
    scale = np.asarray(d["water.attenuation_scale"])
    d_l = np.asarray(light_distance_m(d))
    target = geometry * weights.table(scale * d_l, 0)
    to_sensor = geometry * _radiance_to_sensor_factor(d, weights)
    path = scale * (d_l + d["operation.altitude_m"])
    return target, to_sensor * weights.table(path, 1), to_sensor * weights.table(path, 2) * d.sensor.pixel_area_m2


def extended_on_axis_quantities(d: Design, weights: SpectralWeights):
    """The extended chain's (target irradiance at the target's centre [W/m²], sensor irradiance [W/m²], target
    electron rate, veiling-light electron rate [e⁻/s]) of the on-axis pixel (of the bare sensor)."""
    chain = extended.Chain(d, weights)
    port = housing_transmittance(d)
    if extended.is_bare(d):
        direct, veil = chain.bare_rates(port)
        irradiance = sum(chain.bare_rates(port, watts=True))
    else:
        lens = broadband_factor(d, "lens.transmittance")
        centre = (np.zeros(1), np.zeros(1), port, lens)
        direct, veil = (x[..., 0] for x in chain.pixel_rates(*centre))
        irradiance = sum(chain.pixel_rates(*centre, watts=True))[..., 0]
    return chain.target_irradiance(weights), irradiance, direct, veil


def on_axis_electron_rate(d: Design):
    """Electron rate [e⁻/s] of the on-axis pixel (extended: target and veiling light; the bare sensor's mean),
    before any clipping (μ_e = rate · t_exp)."""
    weights = spectral_weights(d)
    if d["model.kind"] == "extended":
        _, _, direct, veil = extended_on_axis_quantities(d, weights)
        return direct + veil
    return on_axis_quantities(d, weights)[2]


def extended_image_rates(d: Design, weights: SpectralWeights | None = None):
    """(target, veiling light) mean electron rates per pixel [e⁻/s] over the sensor in the extended chain (a
    16 × 16 midpoint grid over the whole frame; the bare sensor is uniform)."""
    weights = spectral_weights(d) if weights is None else weights
    chain = extended.Chain(d, weights)
    port = housing_transmittance(d)
    if extended.is_bare(d):
        return chain.bare_rates(port)
    x, y = chain.image_positions()
    direct, veil = chain.pixel_rates(x, y, port, broadband_factor(d, "lens.transmittance"))
    return direct.mean(axis=-1), veil.mean(axis=-1)


def paper(d: Design) -> Design:
    """The design under the paper's chain ([model] kind = "paper"): every extended-model key is then ignored."""
    return d.with_values(**{"model.kind": "paper"})


def circle_of_confusion_m(d: Design):
    """The acceptable circle of confusion on the sensor [m]: `operation.circle_of_confusion_mm`, by default the
    sensor diagonal / 1500."""
    coc = d["operation.circle_of_confusion_mm"]
    return d.sensor.diagonal_m / 1500 if coc is None else np.asarray(coc) * 1e-3


def port_geometry(d: Design):
    """(port, n_w, flat, dome, decenter_z_m) for the paraxial formulas of `uwlab.model.optics` and
    `uwlab.model.focus`: flat = (air_gap_m, thickness_m, port_index); dome = (radius_m, thickness_m, port_index)
    or None for a flat port; decenter_z_m the pupil's axial offset from the dome's centre."""
    h = d.values["housing"]
    flat = (h["flat_air_gap_mm"] * 1e-3, h["flat_thickness_mm"] * 1e-3, h["port_index"])
    dome = None
    if h["port"] == "dome":
        dome = (h["dome_radius_mm"] * 1e-3, h["dome_thickness_mm"] * 1e-3, h["port_index"])
    return h["port"], h["water_index"], flat, dome, h["dome_decenter_mm"][2] * 1e-3
