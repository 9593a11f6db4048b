"""The simulated EMVA 1288 bench: what the simulated camera and spectrometer see on a `uwlab.model.bench.Bench` — a
bare sensor in air under a uniform diffuse disk source, the spectrometer at the sensor plane.

It offers the scene interface the simulated rig uses (`uwlab.sim.scene.RigScene`): the electron-rate map of
the full sensor (the on-axis rate times the disk's exact falloff; for a colour sensor a raw Bayer mosaic, each
pixel's rate through its own filter's QE, as `uwlab.sim.scene.RigScene` renders one), the spectrum at the ``sensor``
position, the light state, the ``[sim]`` settings (``seed``, ``light_gamma``) and the ground truth, including the
photon-weighted quantum efficiency the characterisation must recover (a colour sensor's per channel too).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uwlab.drivers.camera.pixels import bayer_mosaic
from uwlab.sim.rig_state import RigState, WarmUp
from uwlab.sim.settings import SimSettings
from uwlab.errors import ConfigError
from uwlab.model.bench import Bench, build_bench
from uwlab.model.schema import parse
from uwlab.model.sensor import SensorProfile

SENSOR_POSITION = "sensor"


class BenchScene:
    """The bench, its ``[sim]`` settings and the shared light state."""

    def __init__(self, design: Bench, sim, state: RigState | None = None):
        self.design = design
        self.sim = sim
        self.state = state or RigState()

    @classmethod
    def from_dict(cls, raw: dict, base_dir: Path | None = None, state: RigState | None = None) -> BenchScene:
        return cls(build_bench(raw, base_dir), parse(SimSettings, raw.get("sim", {}), "sim"), state)

    @property
    def sensor(self) -> SensorProfile:
        return self.design.sensor

    def use(self, design: Bench, bare: bool) -> None:
        """Put a sweep's bench on the rig (the bench's sensor is always bare)."""
        self.design = design

    def sensor_realism(self) -> dict:
        """No `SimTruth` overrides: the bench characterises the sensor profile as it is."""
        return {}

    def warm_up(self) -> WarmUp:
        """The bench's light does not drift (a stabilised source, as the standard's set-up assumes)."""
        return WarmUp()

    def flux_fraction(self) -> float:
        """The light's current output as a fraction of its rated flux (0 when off)."""
        return self.state.light.effective_fraction

    def on_axis_rate_e_per_s(self, flux_fraction: float = 1.0) -> float:
        return self.design.on_axis_rate_e_per_s(flux_fraction)

    def electron_rate_map(self, shape_yx: tuple[int, int], flux_fraction: float = 1.0) -> np.ndarray:
        """Per-pixel electron rate [e⁻/s] (float32) for an image of ``shape_yx`` covering the full sensor; for a
        colour sensor the raw Bayer mosaic (`SensorProfile.bayer`), each site at its own channel's rate."""
        ny, nx = shape_yx
        size_x, size_y = self.sensor.size_m
        x = (np.arange(nx) + 0.5) / nx * size_x - size_x / 2
        y = (np.arange(ny) + 0.5) / ny * size_y - size_y / 2
        relative = self.design.relative_irradiance(np.hypot(x[None, :], y[:, None]))
        if not self.sensor.color:
            return (self.on_axis_rate_e_per_s(flux_fraction) * relative).astype(np.float32)
        planes = {
            colour: (self.design.on_axis_rate_e_per_s(flux_fraction, channel) * relative).astype(np.float32)
            for colour, channel in (("R", "red"), ("G", "green"), ("B", "blue"))
        }
        return bayer_mosaic(self.sensor.bayer, planes)

    def board_roi(self, shape_yx: tuple[int, int]) -> tuple[int, int, int, int]:
        """The whole image: the bench has no target board."""
        return 0, 0, shape_yx[1], shape_yx[0]

    def set_lens(self, **_) -> None:
        raise ConfigError("lens", "set", "the EMVA 1288 bench has no lens")

    def spectral_irradiance(self, position: str, flux_fraction: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """(wavelength_nm, irradiance_w_m2_nm) at the sensor plane (the only position of the bench)."""
        if position != SENSOR_POSITION:
            raise ConfigError("position", position, f"the bench's spectrometer reads at the '{SENSOR_POSITION}' plane")
        return self.design.sensor_irradiance_w_m2_nm(flux_fraction)

    def truth(self) -> dict:
        """The bench's ground truth for checking a characterisation; a colour sensor's photon-weighted QE per
        channel as ``quantum_efficiency_<red|green|blue>`` (``quantum_efficiency``: its combined curve's)."""
        b = self.design
        nm, e = b.sensor_irradiance_w_m2_nm()
        channels = ("red", "green", "blue") if self.sensor.color else ()
        return {
            **{f"quantum_efficiency_{c}": b.quantum_efficiency(c) for c in channels},
            "quantum_efficiency": b.quantum_efficiency(),
            "bench_f_number": b.f_number,
            "source_diameter_mm": b.source_diameter_mm,
            "source_distance_mm": b.distance_mm,
            "wavelength_nm": b.wavelength_nm,
            "fwhm_nm": b.fwhm_nm,
            "sensor_irradiance_w_m2": float(np.trapezoid(e, nm)),
            "on_axis_rate_e_per_s": self.on_axis_rate_e_per_s(),
        }
