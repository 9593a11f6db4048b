"""The EMVA 1288 measurement bench: a bare sensor in air under a uniform, diffuse, disk-shaped light source
(EMVA 1288 Release 4.0 Linear §6.1–6.4, Fig. 4a).

A rig config with a ``[bench]`` table (instead of the design sections of an underwater rig) describes it:

- ``f_number`` (default 8, "Measurements performed according to the standard require an f-number of 8", eq. 46) and
  ``source_diameter_mm`` D; the source is at d = N·D from the sensor plane, and the sensor's diagonal must not exceed
  D ("the diameter of the sensor area should not be larger than the diameter of the opening of the light source");
- the source's spectrum: a Gaussian line at ``wavelength_nm`` with ``fwhm_nm`` (§6.2: narrow band, FWHM < 50 nm);
- ``radiance_w_m2_sr``: the source's radiance at light level 1.

Irradiance at the sensor plane: E = π L / (1 + 4 N²) on the axis, falling off towards the edge of the sensor as the
exact view factor of a Lambertian disk (`uwlab.model.optics.disk_source_irradiance_factor`); a spectrometer or
photodiode "put at the place of the image sensor" (§6.4) reads the on-axis value. Electron rate of a pixel:
A ∫ E(λ) λ/(h c) η(λ) dλ with the sensor profile's QE curve; the photon-weighted quantum efficiency the bench
measures is ∫ E λ η dλ / ∫ E λ dλ (the η that Release 4.0 Linear eq. 52 recovers). A colour sensor's pixels each
see the source through their own filter: η is then the ``red``, ``green`` or ``blue`` QE curve of the profile, one
photon-weighted η per channel (Release 4.0 Linear §1.2: each colour channel is a sensor of its own).

Config keys besides ``[bench]``: ``[sensor] profile`` and the simulation's ``[sim]`` (``seed``, ``light_gamma``).
A plan sweeping on a bench must be lensless (``lens = "none"``).
"""

from __future__ import annotations

from typing import Annotated

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pydantic import Field

from uwlab.errors import ConfigError
from uwlab.model.grid import WavelengthGrid
from uwlab.model.optics import BARE_SENSOR_F_NUMBER, disk_source_irradiance_factor
from uwlab.model.photometry import photons_per_joule
from uwlab.model.schema import FNumber, HousingMm, Schema, WavelengthNm, parse, limits
from uwlab.model.sensor import SensorProfile, load_sensor_profile

ALLOWED_SECTIONS = ("bench", "sensor", "sim", "lens", "operation")
# A light source's band: the standard asks for less than 50 nm FWHM (§6.2); above 200 nm it is not a band.
BandwidthNm = Annotated[float, limits(0.1, 200.0, "nm")]
# Radiance of the source: an integrating sphere gives 1e-3–1e3 W m⁻² sr⁻¹; 1e6 is the sun's disk in W/m²/sr order.
RadianceWM2Sr = Annotated[float, limits(1e-9, 1e6, "W/m²/sr")]


class BenchTable(Schema):
    """A rig config's ``[bench]`` table (module docstring)."""

    f_number: FNumber = Field(8.0, description="f-number of the source geometry, d / D (eq. 46)")
    source_diameter_mm: HousingMm = Field(description="diameter D of the source's opening [mm]")
    wavelength_nm: WavelengthNm = Field(description="centre of the source's band [nm]")
    fwhm_nm: BandwidthNm = Field(description="full width at half maximum of the band [nm]")
    radiance_w_m2_sr: RadianceWM2Sr = Field(description="the source's radiance at light level 1 [W m⁻² sr⁻¹]")


@dataclass(frozen=True)
class Bench:
    """A validated bench config (see the module docstring). ``values`` holds the config's sections for the dataset's
    record of the rig."""

    f_number: float
    source_diameter_mm: float
    wavelength_nm: float
    fwhm_nm: float
    radiance_w_m2_sr: float
    sensor: SensorProfile
    values: dict = field(repr=False)

    @property
    def distance_mm(self) -> float:
        return self.f_number * self.source_diameter_mm

    def grid(self) -> WavelengthGrid:
        """A 0.25 nm grid over ±5 σ of the line (σ = FWHM / 2.355)."""
        sigma = self.fwhm_nm / (2.0 * math.sqrt(2.0 * math.log(2.0)))
        return WavelengthGrid(max(1.0, self.wavelength_nm - 5 * sigma), self.wavelength_nm + 5 * sigma, 0.25)

    def sensor_irradiance_w_m2_nm(self, level_fraction: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """(λ [nm], E(λ) [W m⁻² nm⁻¹]) on the sensor plane, on axis, at a flux fraction of the source."""
        grid = self.grid()
        sigma = self.fwhm_nm / (2.0 * math.sqrt(2.0 * math.log(2.0)))
        shape = np.exp(-0.5 * ((grid.nm - self.wavelength_nm) / sigma) ** 2)
        radiance = self.radiance_w_m2_sr * shape / np.sum(shape * grid.w_nm)
        return grid.nm, level_fraction * radiance * float(disk_source_irradiance_factor(self.f_number))

    def relative_irradiance(self, r_m) -> np.ndarray:
        """E(r)/E(0) at a distance ``r_m`` from the axis on the sensor plane."""
        d_m = self.distance_mm * 1e-3
        return disk_source_irradiance_factor(
            self.f_number, np.asarray(r_m, float) / d_m
        ) / disk_source_irradiance_factor(self.f_number)

    def on_axis_rate_e_per_s(self, level_fraction: float = 1.0, channel: str = "combined") -> float:
        """Photo-electrons per second of the on-axis pixel: A ∫ E λ/(h c) η dλ, with η the QE of ``channel`` (a
        colour sensor's "red", "green" or "blue" pixel; "combined": the profile's mono or combined curve)."""
        grid = self.grid()
        nm, e = self.sensor_irradiance_w_m2_nm(level_fraction)
        qe = self.sensor.qe_on(grid, channel)
        return float(self.sensor.pixel_area_m2 * np.sum(e * photons_per_joule(nm) * qe * grid.w_nm))

    def quantum_efficiency(self, channel: str = "combined") -> float:
        """The photon-weighted η of the sensor (or of a colour sensor's ``channel``) under this source:
        ∫ E λ η dλ / ∫ E λ dλ."""
        grid = self.grid()
        nm, e = self.sensor_irradiance_w_m2_nm()
        weight = e * photons_per_joule(nm) * grid.w_nm
        return float(np.sum(weight * self.sensor.qe_on(grid, channel)) / np.sum(weight))


def is_bench(raw: dict) -> bool:
    """Whether a rig config describes an EMVA 1288 bench (it has a ``[bench]`` table)."""
    return isinstance(raw.get("bench"), dict)


def build_bench(raw: dict, base_dir: Path | None = None) -> Bench:
    """Validate a bench config (``[bench]``, ``[sensor] profile``; a plan's lens must be "none"); `ConfigError`
    names the key."""
    for section in raw:
        if section not in ALLOWED_SECTIONS:
            raise ConfigError(section, "...", f"not a section of a bench rig ({', '.join(ALLOWED_SECTIONS[:3])})")
    values = parse(BenchTable, raw["bench"], "bench").model_dump()
    lens = raw.get("lens", {})
    if lens.get("f_number", BARE_SENSOR_F_NUMBER) != BARE_SENSOR_F_NUMBER or lens.get("focal_length_mm") is not None:
        raise ConfigError("lens", lens, 'the EMVA 1288 bench measures the bare sensor: use lens = "none"')
    profile = (raw.get("sensor") or {}).get("profile")
    if not isinstance(profile, str):
        raise ConfigError("sensor.profile", profile, "required: the sensor profile of the camera on the bench")
    sensor = load_sensor_profile(profile, base_dir)
    if sensor.diagonal_m * 1e3 > values["source_diameter_mm"]:
        raise ConfigError(
            "bench.source_diameter_mm",
            values["source_diameter_mm"],
            f"smaller than the sensor's diagonal {sensor.diagonal_m * 1e3:.1f} mm (Release 4.0 §6.1)",
        )
    return Bench(**values, sensor=sensor, values={"bench": values, "sensor": {"profile": profile}})
