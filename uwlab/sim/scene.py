"""The simulated rig's scene: what the simulated camera and spectrometer see.

A rig config is a design config (the sections of `uwlab design`, the nominal rig a fit starts from) plus the
simulation's ground truth: a ``[world]`` section (`uwlab.sim.world`: the ``ideal`` world renders from the
design model's paper chain as described below, whatever the rig's [model]; ``tank`` and ``turbid`` from the tank
renderer, `uwlab.sim.tank`) and a `[sim]` section:
``seed`` (fixed-pattern noise maps), ``light_gamma`` (flux fraction = level^γ), ``board_size_m`` [x, y] (the
target board on the target plane, centred on the axis), ``surround_reflectance`` (outside the board) and
``light_efficiency`` (the true emitted flux as a fraction of the rated `light.luminous_flux_lm`: a ground truth
that a model fit starting from the rated lumens should recover).

Images: the per-pixel electron rate is the model's on-axis rate (configured distances and incidence) times the
relative profile of `uwlab.model.chain.electron_rate_at_radius` (cos⁴ falloff, oblique paths, beam cut-off),
with the board's reflectance inside its footprint and the surround's outside. Spectra: at the target, the
irradiance on a board facing the light (normal incidence); at the camera, π L_w, the irradiance from a
Lambertian target filling the meter's field; at the sensor, the irradiance on the sensor plane behind the lens
(on axis). All scale linearly with the light's flux fraction.

`load_scene` reads any rig config: a ``[bench]`` table makes it the EMVA 1288 bench (`uwlab.sim.bench`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from uwlab.drivers.camera.pixels import bayer_mosaic
from uwlab.model.bench import is_bench
from uwlab.sim.bench import BenchScene
from uwlab.sim.rig_state import RigState, WarmUp
from uwlab.sim.settings import SimSettings
from uwlab.sim.tank import TankWorld
from uwlab.model.config import design_sections
from uwlab.sim.world import WorldSettings, world_settings
from uwlab.errors import ConfigError
from uwlab.model.data import config_dir, read_toml
from uwlab.model.build import build_design
from uwlab.model.chain import effective_focal_length_m, electron_rate_at_radius, on_axis_electron_rate, paper
from uwlab.model.design import Design
from uwlab.model.evaluation import SPECTROMETER_POSITIONS, stage_spectra
from uwlab.model.optics import NO_LENS
from uwlab.model.schema import FNumber, FocalLengthMm, check, parse
from uwlab.model.sensor import SensorProfile

DEFAULT_RIG = "rigs/sim-tank.toml"


@dataclass(eq=False)
class RigScene:
    """The simulated rig: a scalar design, simulation settings, the world and the shared light state."""

    design: Design
    sim: SimSettings
    state: RigState = field(default_factory=RigState)
    no_lens: bool = False
    world: WorldSettings = field(default_factory=WorldSettings)
    tank: TankWorld | None = field(default=None, repr=False)
    _profile: tuple | None = field(default=None, repr=False)

    @classmethod
    def from_toml(
        cls, path: str | Path | None = None, state: RigState | None = None, world: str | None = None
    ) -> RigScene:
        """Load a rig config (None: the default simulated tank, configs/rigs/sim-tank.toml); `world` replaces its
        [world] preset."""
        path = Path(path) if path is not None else config_dir() / DEFAULT_RIG
        return cls.from_dict(read_toml(path, "--config"), path.resolve().parent, state, world)

    @classmethod
    def from_dict(
        cls, raw: dict, base_dir: Path | None = None, state: RigState | None = None, world: str | None = None
    ) -> RigScene:
        """A rig from its config dict (design sections + [sim] + [world]); relative paths resolve against
        base_dir; `world` replaces the [world] preset."""
        sim = parse(SimSettings, raw.get("sim", {}), "sim")
        settings = world_settings(raw.get("world"), world)
        design = build_design(design_sections(raw), base_dir)
        tank = None if settings.rendered_by_model else TankWorld(design, sim, settings, base_dir)
        return cls(design=design, sim=sim, state=state or RigState(), world=settings, tank=tank)

    def use(self, design: Design, bare: bool) -> None:
        """Put a sweep's design on the rig (its sensor and lens; `bare`: no lens); images are re-rendered."""
        self.design = design
        self.no_lens = bare
        self._profile = None

    def sensor_realism(self) -> dict:
        """`SimTruth` fields of the world's sensor realism (DSNU, PRNU, hot pixels, non-linearity); none unless the
        world renders it."""
        if self.tank is None or not self.world.on("sensor_realism"):
            return {}
        w = self.world
        keys = ("dsnu_e", "prnu_percent", "hot_pixel_fraction", "hot_pixel_dark_current_e_per_s")
        return {"nonlinearity": w.nonlinearity_at_full_well, **{key: getattr(w, key) for key in keys}}

    def warm_up(self) -> WarmUp:
        """The light's warm-up drift in this world (none unless the world renders it)."""
        if self.tank is None or not self.world.on("warmup_drift"):
            return WarmUp()
        return WarmUp(self.world.warmup_amplitude, self.world.warmup_switch_ons)

    @property
    def sensor(self) -> SensorProfile:
        return self.design.sensor

    def set_lens(self, focal_length_mm: float | None = None, f_number: float | None = None) -> None:
        """Change the simulated lens (as an operator would on a manual lens); cached images are re-rendered."""
        changes = {}
        if focal_length_mm is not None:
            changes["lens.focal_length_mm"] = check(FocalLengthMm, focal_length_mm, "lens.focal_length_mm")
        if f_number is not None:
            changes["lens.f_number"] = check(FNumber, f_number, "lens.f_number")
        self.design = self.design.with_values(**changes)
        self.no_lens = False
        self._profile = None

    def remove_lens(self) -> None:
        """Take the lens off: the bare sensor sees the board's radiance field, E = π L_a (the camera equation
        `uwlab.model.optics.NO_LENS`), uniform over the sensor (the board is taken to fill the field)."""
        self.design = self.design.with_values(**NO_LENS.overrides())
        self.no_lens = True
        self._profile = None

    def flux_fraction(self) -> float:
        """The light's current output as a fraction of its rated flux (0 when off)."""
        return self.state.light.effective_fraction

    def level_to_flux_fraction(self, level: float) -> float:
        return float(level) ** self.sim.light_gamma

    def on_axis_rate_e_per_s(self, flux_fraction: float = 1.0) -> float:
        """The electron rate [e⁻/s] of the image centre (of a bare sensor) at this flux fraction: the model's
        on-axis rate in the ideal world, the tank's in a tank world."""
        if self.tank is not None:
            return flux_fraction * self.tank.centre_rate(self.design, self.no_lens)
        return flux_fraction * self.sim.light_efficiency * float(on_axis_electron_rate(paper(self.design)))

    def _magnification(self) -> float:
        """Object size on the target plane per unit image size (pinhole with the effective focal length)."""
        return float(self.design["operation.altitude_m"]) / float(effective_focal_length_m(self.design))

    def electron_rate_map(self, shape_yx: tuple[int, int], flux_fraction: float = 1.0) -> np.ndarray:
        """Per-pixel electron rate [e⁻/s] (float32) for an image of `shape_yx` covering the full sensor."""
        shape = (int(shape_yx[0]), int(shape_yx[1]))
        if self._profile is None or self._profile[0] != shape:
            self._profile = (shape, self._render(shape))
        return self._profile[1] * np.float32(flux_fraction)

    def _render(self, shape_yx: tuple[int, int]) -> np.ndarray:
        if self.sensor.color and self.design["sensor.channel"] == "combined":
            return self._mosaic(shape_yx)
        if self.tank is not None:
            return self.tank.rate_map(self.design, self.no_lens, shape_yx)
        if self.no_lens:
            return np.full(shape_yx, self.on_axis_rate_e_per_s(), np.float32)
        d = paper(self.design)
        ny, nx = shape_yx
        size_x, size_y = d.sensor.size_m
        x = (np.arange(nx) + 0.5) / nx * size_x - size_x / 2
        y = (np.arange(ny) + 0.5) / ny * size_y - size_y / 2
        r = np.hypot(x[None, :], y[:, None])
        radii = np.linspace(0.0, float(r.max()), 512)
        profile = electron_rate_at_radius(d, radii)
        relative = np.interp(r, radii, profile / profile[0])
        magnification = self._magnification()
        half_x, half_y = (s / 2 / magnification for s in self.sim.board_size_m)
        board = (np.abs(x)[None, :] <= half_x) & (np.abs(y)[:, None] <= half_y)
        board_reflectance = d["target.reflectance"]
        if isinstance(board_reflectance, str):
            raise ConfigError("target.reflectance", board_reflectance, "the simulated rig needs a number")
        surround = self.sim.surround_reflectance / board_reflectance if board_reflectance > 0 else 0.0
        contrast = np.where(board, 1.0, surround)
        return (self.on_axis_rate_e_per_s() * relative * contrast).astype(np.float32)

    def _mosaic(self, shape_yx: tuple[int, int]) -> np.ndarray:
        """A colour sensor's raw image: each pixel's rate through its own filter (the sensor's ``red``, ``green``
        or ``blue`` QE) on the sensor's Bayer layout (`SensorProfile.bayer`), as a raw Bayer camera delivers it."""
        design = self.design
        planes = {}
        try:
            for colour, channel in (("R", "red"), ("G", "green"), ("B", "blue")):
                self.design = design.with_values(**{"sensor.channel": channel})
                planes[colour] = self._render(shape_yx)
        finally:
            self.design = design
        return bayer_mosaic(self.sensor.bayer, planes)

    def board_roi(self, shape_yx: tuple[int, int]) -> tuple[int, int, int, int]:
        """The board's footprint in an image of `shape_yx` as (x, y, width, height) pixels."""
        if self.tank is not None:
            return self.tank.board_roi(self.design, shape_yx)
        d = self.design
        ny, nx = shape_yx
        size_x, size_y = d.sensor.size_m
        magnification = self._magnification()
        w = min(nx, int(self.sim.board_size_m[0] / magnification / size_x * nx))
        h = min(ny, int(self.sim.board_size_m[1] / magnification / size_y * ny))
        return ((nx - w) // 2, (ny - h) // 2, w, h)

    def spectral_irradiance(self, position: str, flux_fraction: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """(wavelength_nm, irradiance_w_m2_nm) a spectrometer measures at `position` (`SPECTROMETER_POSITIONS`)."""
        if position not in SPECTROMETER_POSITIONS:
            raise ConfigError("position", position, f"must be one of {', '.join(SPECTROMETER_POSITIONS)}")
        if self.tank is not None:
            if position == "sensor":
                raise ConfigError(
                    "position",
                    position,
                    "the tank world's spectrometer is at the target or the "
                    "camera; the sensor plane is the EMVA 1288 bench's (configs/rigs/sim-emva-bench.toml)",
                )
            wavelength_nm, irradiance = self.tank.spectral_irradiance(self.design, position)
            return wavelength_nm, flux_fraction * irradiance
        spectra = stage_spectra(paper(self.design))
        if position == "target":
            irradiance = spectra["facing_light_w_m2_nm"]
        elif position == "sensor":
            irradiance = spectra["sensor_irradiance_w_m2_nm"]
        else:
            irradiance = np.pi * spectra["return_radiance_w_m2_sr_nm"]
        return spectra["wavelength_nm"], flux_fraction * self.sim.light_efficiency * irradiance


def load_scene(path: str | Path | None = None, state: RigState | None = None):
    """The scene of a rig config (None: the default simulated tank): a `RigScene`, or for a config with a
    ``[bench]`` table the EMVA 1288 bench (`uwlab.sim.bench.BenchScene`)."""
    path = Path(path) if path is not None else config_dir() / DEFAULT_RIG
    raw = read_toml(path, "--config")
    if is_bench(raw):
        return BenchScene.from_dict(raw, path.resolve().parent, state)
    return RigScene.from_dict(raw, path.resolve().parent, state)
