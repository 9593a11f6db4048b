"""Evaluating a design: every output of `uwlab design` (`evaluate`) and the spectra along the chain
(`stage_spectra`), for the paper's chain or the extended one (`uwlab.model.extended`)."""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np

from uwlab.model import extended, focus, optics
from uwlab.model import port as port_model
from uwlab.model.budget import light_budget
from uwlab.model.chain import (
    beam_half_angle_rad,
    circle_of_confusion_m,
    effective_focal_length_m,
    extended_image_rates,
    extended_on_axis_quantities,
    housing_transmittance,
    irradiance_geometry,
    light_distance_m,
    on_axis_quantities,
    port_geometry,
)
from uwlab.model.design import Design
from uwlab.model.image_average import image_average_rate
from uwlab.model.sensor import response_dn, snr
from uwlab.model.weights import broadband_factor, spectral_weights


def evaluate(d: Design) -> dict[str, np.ndarray]:
    """All design outputs (the keys of `uwlab design --json`) as arrays broadcast over the design's grid axes."""
    weights = spectral_weights(d)
    sensor = d.sensor
    op = d.values["operation"]
    f_eff = effective_focal_length_m(d)
    size = dict(zip("xy", sensor.size_m, strict=True))
    res = dict(zip("xy", sensor.resolution_px, strict=True))
    fov = {a: optics.angular_fov_rad(size[a], f_eff) for a in "xy"}
    d_c = op["altitude_m"]
    fov_m = {a: optics.spatial_fov_m(fov[a], d_c) for a in "xy"}
    axis = op["motion_axis"]
    speed = np.asarray(op["speed_m_s"], float)
    with np.errstate(divide="ignore"):
        max_exposure = np.where(speed > 0, op["max_blur_px"] * fov_m[axis] / (speed * res[axis]), np.inf)
    min_framerate = speed / (fov_m[axis] * (1 - np.asarray(op["overlap"])))
    if isinstance(op["exposure_s"], str):
        exposure = np.clip(max_exposure, sensor.exposure_min_us * 1e-6, sensor.exposure_max_us * 1e-6)
    else:
        exposure = np.asarray(op["exposure_s"], float)

    coc_m = circle_of_confusion_m(d)
    f_m = d["lens.focal_length_mm"] * 1e-3
    port, n_w, flat, dome, decenter_z = port_geometry(d)
    near, far = optics.dof_underwater(d_c, f_m, d["lens.f_number"], coc_m, port, n_w, dome, flat)
    min_n = None
    if op["min_dof_m"] is not None:
        min_n = optics.min_f_number(d_c, f_m, coc_m, op["min_dof_m"], port, n_w, dome, flat=flat)
    virtual = port_model.dome_virtual_distance(d_c, dome[0], dome[1], n_w, dome[2]) if dome else None
    focus_image = focus.target_image_distance_m(d_c, port, n_w, flat, dome, decenter_z)
    min_focus = d["lens.min_focus_distance_m"]
    close_up = focus.close_up_lens_dpt(focus_image, min_focus) if min_focus is not None else None

    bits = d["sensor.bit_depth"]
    k = sensor.gain_k(d["sensor.gain_db"], bits)
    dark = sensor.dark_dn(bits)
    extras = {}
    if d["model.kind"] == "extended":
        target, sensor_irradiance, rate, veil = extended_on_axis_quantities(d, weights)
        mu_e, mu_y, saturated, snr_value, veil_e = _extended_response(rate, veil, exposure, k, dark, bits, sensor)
        image_rate, image_veil = extended_image_rates(d, weights)
        image_e, image_y, _, image_snr, image_veil_e = _extended_response(
            image_rate, image_veil, exposure, k, dark, bits, sensor
        )
        extras = {"veil_electrons": veil_e}
        image_extras = {"veil_electrons": image_veil_e}
    else:
        target, sensor_irradiance, rate = on_axis_quantities(d, weights)
        mu_e_raw = rate * exposure
        mu_y, saturated = response_dn(mu_e_raw, k, dark, sensor.saturation_e, bits)
        mu_e = np.minimum(mu_e_raw, sensor.saturation_e)
        snr_value = snr(mu_e, sensor.dark_noise_e, k)
        image_raw = image_average_rate(d, weights) * exposure
        image_y, _ = response_dn(image_raw, k, dark, sensor.saturation_e, bits)
        image_e = np.minimum(image_raw, sensor.saturation_e)
        image_snr = snr(image_e, sensor.dark_noise_e, k)
        image_extras = {}
    with np.errstate(divide="ignore"):
        snr_db = 20 * np.log10(snr_value)
    return {
        "effective_focal_length_mm": f_eff * 1e3,
        "fov_deg": {a: np.degrees(fov[a]) for a in "xy"},
        "fov_m": fov_m,
        "max_exposure_s": max_exposure,
        "exposure_s": exposure,
        "min_framerate_hz": min_framerate,
        "dof_m": {"near": near, "far": far},
        "min_f_number_for_dof": min_n,
        "dome_virtual_image_m": virtual,
        "focus_image_m": focus_image,
        "focus_setting_m": focus.focus_setting_m(focus_image, min_focus),
        "close_up_lens_dpt": close_up,
        "target_irradiance_w_m2": target,
        "sensor_irradiance_w_m2": sensor_irradiance,
        "mean_electrons": mu_e,
        "mean_dn": mu_y,
        "mean_fraction": mu_y / (2.0 ** np.asarray(bits) - 1),
        "saturated": saturated,
        "snr": snr_value,
        "snr_db": snr_db,
        **extras,
        "image_average": {"mean_electrons": image_e, "mean_dn": image_y, "snr": image_snr, **image_extras},
        "light_budget_stops": light_budget(d, weights, fov_m),
    }


def _extended_response(rate, veil, exposure, k, dark, bits, sensor):
    """(μ_e, μ_y, saturated, SNR, μ_veil) of a pixel receiving target and veiling light: the camera records both;
    the SNR is the target's signal over the shot noise of both (`uwlab.model.sensor.snr`). At saturation both are
    clipped in proportion."""
    total_raw = (rate + veil) * exposure
    mu_y, saturated = response_dn(total_raw, k, dark, sensor.saturation_e, bits)
    total = np.minimum(total_raw, sensor.saturation_e)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(total_raw > 0, veil * exposure / total_raw, 0.0)
    veil_e = total * share
    return total, mu_y, saturated, snr(total - veil_e, sensor.dark_noise_e, k, veil_e), veil_e


SpectrometerPosition = Literal["target", "camera", "sensor"]
SPECTROMETER_POSITIONS: tuple[str, ...] = get_args(SpectrometerPosition)


def stage_spectra(d: Design) -> dict[str, np.ndarray]:
    """Spectra along the on-axis chain for a scalar design (for plots and the simulated spectrometer).

    Keys: wavelength_nm; source_w_nm (Φe, all lights); target_irradiance_w_m2_nm (E_t); facing_light_w_m2_nm (the
    irradiance on a board at the target's centre facing the light, E_t / cos θ_i; extended: of every light, on a
    surface across its ray); return_radiance_w_m2_sr_nm (L_w at the camera, before the port; extended: with the
    veiling light); sensor_irradiance_w_m2_nm (E_s); absorbed_w_m2_nm (E_s η).
    """
    if d["model.kind"] == "extended":
        return _extended_spectra(d)
    w = spectral_weights(d)
    grid = d.grid
    c = w.c * d["water.attenuation_scale"]
    beta = beam_half_angle_rad(d)
    flux = d["light.luminous_flux_lm"]
    source = d["light.count"] * flux * w.s_per_lm
    geometry = flux * irradiance_geometry(d, beta, np.cos(np.radians(d["light.incidence_deg"])))
    d_l, d_c = light_distance_m(d), d["operation.altitude_m"]
    e_t = geometry * w.s_per_lm * np.exp(-c * d_l)
    l_w = e_t * w.reflectance * broadband_factor(d, "target.reflectance") / np.pi * np.exp(-c * d_c)
    e_s = (
        l_w
        * housing_transmittance(d)
        / d["housing.water_index"] ** 2
        * w.lens_transmittance
        * broadband_factor(d, "lens.transmittance")
        * optics.lens_irradiance_factor(d["lens.f_number"])
    )
    return {
        "wavelength_nm": grid.nm,
        "source_w_nm": source,
        "target_irradiance_w_m2_nm": e_t,
        "facing_light_w_m2_nm": e_t / np.cos(np.radians(d["light.incidence_deg"])),
        "return_radiance_w_m2_sr_nm": l_w,
        "sensor_irradiance_w_m2_nm": e_s,
        "absorbed_w_m2_nm": e_s * w.qe,
    }


def _extended_spectra(d: Design) -> dict[str, np.ndarray]:
    """`stage_spectra` of the extended chain: at the target's centre and along the on-axis ray (per wavelength)."""
    w = spectral_weights(d)
    chain = extended.Chain(d, w)
    target, facing, radiance = chain.spectra(w)
    lens = broadband_factor(d, "lens.transmittance") * w.lens_transmittance
    e_s = (
        radiance
        * housing_transmittance(d)
        / d["housing.water_index"] ** 2
        * lens
        * optics.lens_irradiance_factor(d["lens.f_number"])
    )
    flux = sum(np.asarray(light.flux_lm) * np.asarray(light.count) for light in chain.lights)
    return {
        "wavelength_nm": d.grid.nm,
        "source_w_nm": flux * w.s_per_lm,
        "target_irradiance_w_m2_nm": target,
        "facing_light_w_m2_nm": facing,
        "return_radiance_w_m2_sr_nm": radiance,
        "sensor_irradiance_w_m2_nm": e_s,
        "absorbed_w_m2_nm": e_s * w.qe,
    }
