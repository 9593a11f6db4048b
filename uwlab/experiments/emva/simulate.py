"""A photon-transfer dataset of the simulated camera, rendered directly with `SimSensor` (no transport).

Uniform illumination (flat electron-rate map) at a list of exposures, each point with L bright and L dark
frames; statistics by `emva_stream`. The sensor's electron rate is ``quantum_efficiency`` × the photon rate,
so the light is recorded as a narrow Gaussian spectrum (``fwhm_nm``) at ``wavelength_nm`` at the camera whose
photon irradiance gives exactly μ_p = rate t_exp / η per pixel. Ground truth goes to ``metadata.sim_truth``.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from uwlab.drivers.sim.camera import SensorConfig, SimSensor, SimTruth, flat_rate_map
from uwlab.experiments.dataset import Dataset, point_row, spectra_frame
from uwlab.experiments.emva.stream import stack_statistics
from uwlab.experiments.saturation import clip_level, sensor_clip_dn
from uwlab.model.photometry import photon_flux

SWEEP_ID = "sim-photon-transfer"


def line_spectrum(photon_irradiance_m2_s: float, wavelength_nm: float, fwhm_nm: float):
    """(λ [nm], E(λ) [W m⁻² nm⁻¹]) of a Gaussian line with the given photon irradiance."""
    sigma = fwhm_nm / (2.0 * np.sqrt(2.0 * np.log(2.0)))
    nm = np.arange(wavelength_nm - 5 * sigma, wavelength_nm + 5 * sigma + 0.25, 0.25)
    shape = np.exp(-0.5 * ((nm - wavelength_nm) / sigma) ** 2)
    return nm, shape * (photon_irradiance_m2_s / photon_flux(nm, shape))


def simulate_photon_transfer(root, truth: SimTruth, *, rate_e_per_s: float, quantum_efficiency: float,
                             exposures_us, frames: int = 2, black_level_dn: float = 32.0,
                             wavelength_nm: float = 525.0, fwhm_nm: float = 20.0, seed: int = 0,
                             force: bool = False) -> Dataset:
    """Render and record the sweep (one row per exposure, dark frames at every exposure) into a dataset; returns
    it open for reading."""
    light = {"on": 1.0}
    sensor = SimSensor(truth, flat_rate_map(rate_e_per_s), lambda: light["on"], seed=seed)
    width, height = truth.resolution_px
    area = (truth.pixel_size_um * 1e-6) ** 2
    nm, spectrum = line_spectrum(rate_e_per_s / (quantum_efficiency * area), wavelength_nm, fwhm_nm)
    plan = {"name": SWEEP_ID, "sweep": [{"id": SWEEP_ID, "kind": "exposure", "frames_per_point": frames,
                                        "values": [float(t) for t in exposures_us]}],
            "sim_photon_transfer": {"rate_e_per_s": rate_e_per_s, "seed": seed}}
    sim_truth = {**asdict(truth), "quantum_efficiency": quantum_efficiency, "rate_e_per_s": rate_e_per_s,
                 "wavelength_nm": wavelength_nm}
    dataset = Dataset.create(root, plan, plan_sha256=hashlib.sha256(json.dumps(plan).encode()).hexdigest(),
                             sim=True, sim_truth={SWEEP_ID: sim_truth}, force=force)
    fmt = f"Mono{truth.bit_depth}"
    clip = clip_level(fmt, native_bits=truth.bit_depth, profile_dn=sensor_clip_dn(
        truth.K_dn_per_e, truth.saturation_e, truth.dark_offset_dn + black_level_dn, truth.bit_depth, fmt))
    for index, exposure_us in enumerate(exposures_us):
        cfg = SensorConfig(float(exposure_us), 0.0, black_level_dn, fmt, 0, 0, width, height)
        light["on"] = 1.0
        bright = stack_statistics((sensor.render(cfg) for _ in range(frames)), clip.dn)
        light["on"] = 0.0
        dark = stack_statistics((sensor.render(cfg) for _ in range(frames)), clip.dn)
        row = point_row(
            sweep_id=SWEEP_ID, point_index=index, kind="exposure", bright=bright, dark=dark, clip=clip,
            camera_backend="sim", camera_id="sim0", camera_model=f"SimCam-{truth.name}",
            sensor_profile=truth.name.lower(), exposure_us=float(exposure_us), gain_db=0.0,
            black_level_dn=black_level_dn, light_level=1.0, light_on=True, bit_depth=truth.bit_depth,
            roi_x=0, roi_y=0, roi_w=width, roi_h=height, exposure_us_readback=float(exposure_us),
            gain_db_readback=0.0, temperature_c=truth.temperature_c,
            irradiance_w_m2=float(np.trapezoid(spectrum, nm)), irradiance_position="camera",
        )
        dataset.append_point(row, spectra_frame(SWEEP_ID, index, [("camera", nm, spectrum)]))
    dataset.finish()
    dataset.close()
    return Dataset.open(root)


def sim_truth_of(root) -> dict:
    """The ground truth recorded by `simulate_photon_transfer`."""
    return Dataset.open(Path(root)).metadata["sim_truth"][SWEEP_ID]
