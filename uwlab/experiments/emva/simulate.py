"""Photon-transfer measurements of the simulated camera, rendered directly with `SimSensor` (no transport): test
equipment whose ground truth the characterisation must recover.

`DirectBench`: a `SimSensor` under an electron-rate map (flat by default; any map, e.g. a vignetted one) whose light is
recorded as a narrow Gaussian spectrum (``fwhm_nm``) at ``wavelength_nm`` at the sensor plane, with the photon
irradiance that gives exactly μ_p = rate t_exp / η per pixel on axis. The clip level comes from the sensor profile
and a frame exposed to twice the full well, as a sweep finds it (`uwlab.experiments.saturation.clip_level`: a
pile-up below the profile's level wins, e.g. for the compressed test non-linearity). It measures points (L bright
and L dark frames), dark points at any temperature (`SimTruth.at_temperature`) and the nonuniformity stacks, each
through `uwlab.experiments.frames.stack`. `simulate_photon_transfer` records a sweep (and a dark-current series) into a
dataset with the ground truth in ``metadata.sim_truth``.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TypedDict

import numpy as np

from uwlab.sim.devices.camera import RateMap, SensorConfig, SimSensor, SimTruth, flat_rate_map
from uwlab.experiments.dataset import Dataset, point_row, spectra_frame
from uwlab.experiments.emva.dark import DarkSeries
from uwlab.experiments.frames.stack import StackStatistics, stack_statistics
from uwlab.experiments.emva.transfer import NonuniformityStack, PhotonTransfer, SpatialSplit
from uwlab.experiments.saturation import ClipLevel, clip_level, sensor_clip_dn
from uwlab.model.photometry import photon_flux

SWEEP_ID = "sim-photon-transfer"
DARK_SWEEP_ID = "sim-dark-current"


class CameraColumns(TypedDict):
    """The dataset columns every point of `simulate_photon_transfer` shares: the camera's identity and settings."""

    camera_backend: str
    camera_id: str
    camera_model: str
    sensor_profile: str
    gain_db: float
    black_level_dn: float
    bit_depth: int
    roi_x: int
    roi_y: int
    roi_w: int
    roi_h: int
    gain_db_readback: float


def line_spectrum(photon_irradiance_m2_s: float, wavelength_nm: float, fwhm_nm: float):
    """(λ [nm], E(λ) [W m⁻² nm⁻¹]) of a Gaussian line with the given photon irradiance."""
    sigma = fwhm_nm / (2.0 * np.sqrt(2.0 * np.log(2.0)))
    nm = np.arange(wavelength_nm - 5 * sigma, wavelength_nm + 5 * sigma + 0.25, 0.25)
    shape = np.exp(-0.5 * ((nm - wavelength_nm) / sigma) ** 2)
    return nm, shape * (photon_irradiance_m2_s / photon_flux(nm, shape))


@dataclass
class DirectBench:
    """A simulated sensor under uniform light of known photon irradiance (see the module docstring)."""

    truth: SimTruth
    rate_e_per_s: float
    quantum_efficiency: float
    rate_map: RateMap | None = None
    black_level_dn: float = 32.0
    wavelength_nm: float = 525.0
    fwhm_nm: float = 20.0
    seed: int = 0

    def __post_init__(self) -> None:
        self.light = {"on": 1.0}
        self._sensors: dict[float, SimSensor] = {}
        area = (self.truth.pixel_size_um * 1e-6) ** 2
        self.spectrum = line_spectrum(
            self.rate_e_per_s / (self.quantum_efficiency * area), self.wavelength_nm, self.fwhm_nm
        )
        self.format = f"Mono{self.truth.bit_depth}"
        profile_dn = sensor_clip_dn(
            self.truth.K_dn_per_e,
            self.truth.saturation_e,
            self.truth.dark_offset_dn + self.black_level_dn,
            self.truth.bit_depth,
            self.format,
        )
        overexposed = self.sensor().render(self.config(2e6 * self.truth.saturation_e / self.rate_e_per_s))
        self.clip: ClipLevel = clip_level(
            self.format, native_bits=self.truth.bit_depth, profile_dn=profile_dn, image=overexposed
        )

    def sensor(self, temperature_c: float | None = None) -> SimSensor:
        """The sensor (same fixed patterns) at ``temperature_c`` (default: the truth's)."""
        t = self.truth.temperature_c if temperature_c is None else float(temperature_c)
        if t not in self._sensors:
            rate_map = self.rate_map or flat_rate_map(self.rate_e_per_s)
            self._sensors[t] = SimSensor(
                self.truth.at_temperature(t), rate_map, lambda: self.light["on"], seed=self.seed
            )
        return self._sensors[t]

    def config(self, exposure_us: float) -> SensorConfig:
        width, height = self.truth.resolution_px
        return SensorConfig(float(exposure_us), 0.0, self.black_level_dn, self.format, 0, 0, width, height)

    def photons(self, exposure_us: float) -> float:
        """μ_p per pixel on axis for ``exposure_us``."""
        return self.rate_e_per_s * exposure_us * 1e-6 / self.quantum_efficiency

    def stack(
        self,
        exposure_us: float,
        frames: int,
        light: bool,
        temperature_c: float | None = None,
        keep_mean_image: bool = False,
    ) -> StackStatistics:
        sensor, cfg = self.sensor(temperature_c), self.config(exposure_us)
        self.light["on"] = 1.0 if light else 0.0
        return stack_statistics((sensor.render(cfg) for _ in range(frames)), self.clip.dn, keep_mean_image)

    def nonuniformity_stack(self, exposure_us: float, frames: int) -> NonuniformityStack:
        """L bright and L dark frames at ``exposure_us`` with their mean images (Release 4.0 §8)."""
        bright = self.stack(exposure_us, frames, True, keep_mean_image=True)
        dark = self.stack(exposure_us, frames, False, keep_mean_image=True)
        return NonuniformityStack(bright, dark, self.photons(exposure_us), exposure_us * 1e-6)

    def photon_transfer(
        self,
        exposures_us,
        frames: int = 2,
        *,
        dark_exposures_us=(),
        dark_frames: int = 2,
        dark_temperatures_c=(),
        stack_exposure_us: float | None = None,
        stack_frames: int = 16,
    ) -> PhotonTransfer:
        """A `PhotonTransfer` measured directly (no dataset): the sweep, its dark series (the sweep's darks plus
        ``dark_exposures_us`` at the truth's temperature and at ``dark_temperatures_c``) and, with
        ``stack_exposure_us``, the nonuniformity stacks."""
        bright = [self.stack(e, frames, True) for e in exposures_us]
        dark = [self.stack(e, frames, False) for e in exposures_us]
        series = [(e, s, self.truth.temperature_c) for e, s in zip(exposures_us, dark, strict=True)]
        for temperature in (self.truth.temperature_c, *dark_temperatures_c):
            series += [
                (e, self.stack(e, dark_frames, False, temperature_c=temperature), temperature)
                for e in dark_exposures_us
            ]
        arr = lambda seq, name: np.array([getattr(x, name) for x in seq], float)  # noqa: E731
        exposures = np.asarray(exposures_us, float)
        return PhotonTransfer(
            photons=np.array([self.photons(e) for e in exposures]),
            exposure_s=exposures * 1e-6,
            mean_dn=arr(bright, "mean_dn"),
            temporal_var_dn2=arr(bright, "temporal_var_dn2"),
            frames=arr(bright, "frames"),
            dark_mean_dn=arr(dark, "mean_dn"),
            dark_temporal_var_dn2=arr(dark, "temporal_var_dn2"),
            dark_frames=arr(dark, "frames"),
            spatial=SpatialSplit.of(bright),
            dark_spatial=SpatialSplit.of(dark),
            dark=DarkSeries(
                np.array([e * 1e-6 for e, _, _ in series]),
                np.array([s.mean_dn for _, s, _ in series]),
                np.array([s.temporal_var_dn2 for _, s, _ in series]),
                np.array([t for _, _, t in series]),
            ),
            bit_depth=self.truth.bit_depth,
            saturated_fraction=arr(bright, "saturated_fraction"),
            mean_diff_dn=arr(bright, "mean_diff_dn"),
            temperature_c=np.full(exposures.size, self.truth.temperature_c),
            stack=None if stack_exposure_us is None else self.nonuniformity_stack(stack_exposure_us, stack_frames),
            width_px=self.truth.resolution_px[0],
            height_px=self.truth.resolution_px[1],
            pixels=self.truth.resolution_px[0] * self.truth.resolution_px[1],
            pixel_area_m2=(self.truth.pixel_size_um * 1e-6) ** 2,
            wavelength_nm=self.wavelength_nm,
            source=f"direct simulation of {self.truth.name}",
        )

    def truth_document(self) -> dict:
        area = (self.truth.pixel_size_um * 1e-6) ** 2
        return {
            **asdict(self.truth),
            "quantum_efficiency": self.quantum_efficiency,
            "rate_e_per_s": self.rate_e_per_s,
            "wavelength_nm": self.wavelength_nm,
            "pixel_area_m2": area,
        }


def simulate_photon_transfer(
    root,
    truth: SimTruth,
    *,
    rate_e_per_s: float,
    quantum_efficiency: float,
    exposures_us,
    frames: int = 2,
    black_level_dn: float = 32.0,
    wavelength_nm: float = 525.0,
    fwhm_nm: float = 20.0,
    seed: int = 0,
    dark_exposures_us=(),
    dark_frames: int = 2,
    dark_temperatures_c=(),
    rate_map: RateMap | None = None,
    force: bool = False,
) -> Dataset:
    """Render and record the sweep (one row per exposure, dark frames at every exposure) and a dark-current sweep
    (``dark_exposures_us`` at the truth's temperature and at each of ``dark_temperatures_c``) into a dataset;
    returns it open for reading."""
    bench = DirectBench(truth, rate_e_per_s, quantum_efficiency, rate_map, black_level_dn, wavelength_nm, fwhm_nm, seed)
    width, height = truth.resolution_px
    nm, spectrum = bench.spectrum
    temperatures = [truth.temperature_c, *dark_temperatures_c]
    sweeps = [
        {"id": SWEEP_ID, "kind": "exposure", "frames_per_point": frames, "values": [float(t) for t in exposures_us]}
    ]
    if len(dark_exposures_us):
        sweeps.append(
            {
                "id": DARK_SWEEP_ID,
                "kind": "dark",
                "frames_per_point": dark_frames,
                "values": [float(t) for _ in temperatures for t in dark_exposures_us],
            }
        )
    plan = {
        "name": SWEEP_ID,
        "sweep": sweeps,
        "sim_photon_transfer": {
            "rate_e_per_s": rate_e_per_s,
            "seed": seed,
            "dark_temperatures_c": [float(t) for t in temperatures],
        },
    }
    dataset = Dataset.create(
        root,
        plan,
        plan_sha256=hashlib.sha256(json.dumps(plan).encode()).hexdigest(),
        sim=True,
        sim_truth={SWEEP_ID: bench.truth_document()},
        force=force,
    )
    common = CameraColumns(
        camera_backend="sim",
        camera_id="sim0",
        camera_model=f"SimCam-{truth.name}",
        sensor_profile=truth.name.lower(),
        gain_db=0.0,
        black_level_dn=black_level_dn,
        bit_depth=truth.bit_depth,
        roi_x=0,
        roi_y=0,
        roi_w=width,
        roi_h=height,
        gain_db_readback=0.0,
    )
    for index, exposure_us in enumerate(exposures_us):
        bright = bench.stack(exposure_us, frames, True)
        dark = bench.stack(exposure_us, frames, False)
        row = point_row(
            sweep_id=SWEEP_ID,
            point_index=index,
            kind="exposure",
            bright=bright,
            dark=dark,
            clip=bench.clip,
            exposure_us=float(exposure_us),
            light_level=1.0,
            light_on=True,
            exposure_us_readback=float(exposure_us),
            temperature_c=truth.temperature_c,
            irradiance_w_m2=float(np.trapezoid(spectrum, nm)),
            irradiance_position="sensor",
            **common,
        )
        dataset.append_point(row, spectra_frame(SWEEP_ID, index, [("sensor", nm, spectrum)]))
    index = 0
    for temperature in temperatures:
        for exposure_us in dark_exposures_us:
            dark = bench.stack(exposure_us, dark_frames, False, temperature_c=temperature)
            row = point_row(
                sweep_id=DARK_SWEEP_ID,
                point_index=index,
                kind="dark",
                bright=dark,
                dark=None,
                clip=bench.clip,
                exposure_us=float(exposure_us),
                light_level=1.0,
                light_on=False,
                exposure_us_readback=float(exposure_us),
                temperature_c=float(temperature),
                **common,
            )
            dataset.append_point(row)
            index += 1
    dataset.finish()
    dataset.close()
    return Dataset.open(root)


def sim_truth_of(root) -> dict:
    """The ground truth recorded by `simulate_photon_transfer`."""
    return Dataset.open(Path(root)).metadata["sim_truth"][SWEEP_ID]
