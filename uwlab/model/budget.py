"""The light budget: where the light goes, stage by stage, in stops (``light_budget_stops`` of
`uwlab design`), the largest loss marked."""

from __future__ import annotations

import numpy as np

from uwlab.model.chain import (
    beam_half_angle_rad,
    effective_focal_length_m,
    housing_transmittance,
    irradiance_geometry,
    light_distance_m,
)
from uwlab.model.design import Design
from uwlab.model.weights import SpectralWeights, broadband_factor

LIGHT_BUDGET_STAGES = (
    "beam_to_view",
    "water_to_target",
    "reflectance",
    "water_to_camera",
    "port",
    "aperture",
    "lens_transmittance",
    "quantum_efficiency",
)


def light_budget(d: Design, weights: SpectralWeights, fov_m: dict) -> dict[str, np.ndarray]:
    """Light lost at each stage of the on-axis chain, in stops (−log₂ of the fraction passed on).

    The fractions multiply to R / Q: R the electron rate of the whole sensor at the on-axis rate (rate × pixels),
    Q the photon rate emitted by the lights. Stages: the beam's on-axis irradiance × the imaged footprint / the
    flux (negative when a beam narrower than the view concentrates more than the footprint's share); water on
    the light path and on the return path, the reflectance and the lens transmittance, each weighted by the
    photon spectrum reaching it; the port, T_port/n_w² · (f_eff/f)² (flat: T_port; the n_w² of the radiance is
    won back by the longer focal length); the aperture, the share of the target's Lambertian radiance entering
    the pupil, f²/(4 N² d_C²); the quantum efficiency, electrons per photon reaching the sensor.
    """
    scale = np.asarray(d["water.attenuation_scale"])
    d_l = np.asarray(light_distance_m(d))
    d_c = np.asarray(d["operation.altitude_m"])
    near, far = scale * d_l, scale * (d_l + d_c)
    table = weights.table
    source = table(np.zeros(1), 3)[0]
    lit, reflected = table(near, 3), table(near, 4)
    returned, transmitted = table(far, 4), table(far, 5)
    beta = beam_half_angle_rad(d)
    beam = (
        irradiance_geometry(d, beta, np.cos(np.radians(d["light.incidence_deg"])))
        / d["light.count"]
        * fov_m["x"]
        * fov_m["y"]
    )
    focal = d["lens.focal_length_mm"] * 1e-3
    fractions = {
        "beam_to_view": beam,
        "water_to_target": lit / source,
        "reflectance": reflected / lit * broadband_factor(d, "target.reflectance"),
        "water_to_camera": returned / reflected,
        "port": housing_transmittance(d) / d["housing.water_index"] ** 2 * (effective_focal_length_m(d) / focal) ** 2,
        "aperture": focal**2 / (4 * np.asarray(d["lens.f_number"]) ** 2 * d_c**2),
        "lens_transmittance": transmitted / returned * broadband_factor(d, "lens.transmittance"),
        "quantum_efficiency": table(far, 2) / transmitted,
    }
    with np.errstate(divide="ignore", invalid="ignore"):
        return {k: -np.log2(np.asarray(v, float)) for k, v in fractions.items()}
