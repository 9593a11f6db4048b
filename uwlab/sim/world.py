"""The simulated rig's world: which physics renders its images and spectra (the rig config's ``[world]``).

Presets:

- ``ideal``: the design model itself renders the rig (`uwlab.sim.scene`): a fit checks the model against
  itself. Every effect below is off.
- ``tank``: the paper's tank, rendered by `uwlab.sim.tank.TankWorld` — physics the design model does not
  share: a 46 cm tank, the camera and the light outside it behind the acrylic wall (exact refraction, air gaps,
  angle-dependent Fresnel losses), the light above the camera, every effect below on, clear fresh water.
- ``turbid``: the tank with added scatterers (`particle_scattering_per_m` at 550 nm).

Effect switches (None: the preset's; each can be turned off or on alone in a tank world): ``beam_profile`` (a
smooth cos-power beam instead of a top-hat cone), ``vignetting`` (cos⁴ and mechanical), ``lens_transmission``
(a spectral lens transmittance instead of the design's broadband number), ``backscatter`` (single-scattering
veiling light), ``stray_light`` (a veil from the tank walls), ``warmup_drift`` (the light's output settling
after it is switched on), ``sensor_realism`` (non-linearity near the full well, hot pixels, DSNU, PRNU).

Magnitudes are fields below; their values and sources are stated in configs/rigs/paper-tank.toml, where every one
is either cited or marked assumed. Lengths in metres in the camera frame: origin at the entrance pupil, x right,
y down, z along the optical axis (the camera looks through the tank's near wall at its far wall).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from uwlab.errors import ConfigError
from uwlab.model.scattering import PHASE_FUNCTIONS
from uwlab.model.schema import DistanceM, Fraction, RefractiveIndex, Schema, invalid, parse, quantity

PRESETS = ("ideal", "tank", "turbid")
EFFECTS = (
    "beam_profile",
    "vignetting",
    "lens_transmission",
    "backscatter",
    "stray_light",
    "warmup_drift",
    "sensor_realism",
)
TURBID_PARTICLE_SCATTERING_PER_M = 1.8

# Limits that catch wrong units: tank walls are millimetres to centimetres thick, offsets within a metre.
OffsetM = quantity(-1.0, 1.0, "m")
GapM = quantity(0.0, 1.0, "m")
WallM = quantity(0.0, 0.1, "m", lo_open=True)
TiltDeg = quantity(-45.0, 45.0, "deg", hint="")
FieldDeg = quantity(0.0, 30.0, "deg", hint="", lo_open=True)
ScatteringPerM = quantity(0.0, 50.0, "1/m")
Exponent = quantity(0.0, 4.0, "", hint="")
SmallFraction = quantity(0.0, 0.5, "", hint="a fraction, not a percentage")
SwitchOns = quantity(0.0, 1e6, "uses", hint="", lo_open=True)
DarkCurrent = quantity(0.0, 1e6, "e-/s")
Electrons = quantity(0.0, 100.0, "e-")
Percent = quantity(0.0, 10.0, "%", hint="a percentage")


class WorldSettings(Schema):
    """The ``[world]`` section (defaults: the paper's tank; see the module docstring)."""

    preset: Literal[PRESETS] = Field("ideal", description="ideal | tank | turbid")
    beam_profile: bool | None = None
    vignetting: bool | None = None
    lens_transmission: bool | None = None
    backscatter: bool | None = None
    stray_light: bool | None = None
    warmup_drift: bool | None = None
    sensor_realism: bool | None = None

    tank_size_m: tuple[DistanceM, DistanceM, DistanceM] = Field((0.46, 0.46, 0.46), description="inner [x, y, z]")
    wall_thickness_m: WallM = 0.0127
    wall_index: RefractiveIndex = 1.49
    camera_gap_m: GapM = Field(0.02, description="entrance pupil to the wall's outer face")
    light_offset_m: tuple[OffsetM, OffsetM] = Field((0.0, -0.10), description="light centre [x, y] (y < 0: above)")
    light_gap_m: GapM = Field(0.005, description="light's front to the wall's outer face")
    light_tilt_deg: TiltDeg = Field(0.0, description="aim tilted from the wall normal towards +y (down)")
    spectrometer_camera_position_m: tuple[OffsetM, OffsetM, GapM] = Field(
        (0.0, 0.07, 0.03), description="camera-side probe [x, y, depth behind the inner wall face]"
    )
    spectrometer_field_deg: FieldDeg = 5.0

    particle_scattering_per_m: ScatteringPerM | None = Field(None, description="added scatterers' b_p at 550 nm")
    particle_scattering_exponent: Exponent = 1.0
    particle_phase_function: Literal[PHASE_FUNCTIONS] = "fournier-forand"

    stray_fraction: SmallFraction = 0.005
    warmup_amplitude: SmallFraction = 0.02
    warmup_switch_ons: SwitchOns = 20.0
    lens_transmittance_csv: str = "../lenses/multicoated-lens_transmittance.csv"
    corner_falloff_at_f2: Fraction = 0.25
    nonlinearity_at_full_well: SmallFraction = 0.01
    hot_pixel_fraction: SmallFraction = 2e-4
    hot_pixel_dark_current_e_per_s: DarkCurrent = 2000.0
    dsnu_e: Electrons = 1.0
    prnu_percent: Percent = 0.5

    @model_validator(mode="after")
    def _ideal_has_no_effects(self):
        if self.preset == "ideal":
            switched = [e for e in EFFECTS if getattr(self, e)]
            if switched or self.particle_scattering_per_m:
                key = (switched or ["particle_scattering_per_m"])[0]
                raise invalid(key, getattr(self, key), 'the ideal world is the design model; use preset = "tank"')
        return self

    @property
    def rendered_by_model(self) -> bool:
        """The ideal world: the design model renders the rig."""
        return self.preset == "ideal"

    def on(self, effect: str) -> bool:
        """Whether `effect` (one of EFFECTS) is rendered."""
        value = getattr(self, effect)
        return (self.preset != "ideal") if value is None else value

    @property
    def particle_b550_per_m(self) -> float:
        """Added scatterers' b_p at 550 nm [1/m]: the field, else the preset's (turbid:
        `TURBID_PARTICLE_SCATTERING_PER_M`, else 0)."""
        if self.particle_scattering_per_m is not None:
            return self.particle_scattering_per_m
        return TURBID_PARTICLE_SCATTERING_PER_M if self.preset == "turbid" else 0.0

    def summary(self) -> dict:
        """What was rendered: the preset, each effect on or off, the added scattering (for metadata and reports)."""
        return {
            "preset": self.preset,
            "effects": {e: self.on(e) for e in EFFECTS},
            "particle_scattering_per_m": self.particle_b550_per_m,
        }


def world_settings(raw: dict | None, preset: str | None = None) -> WorldSettings:
    """Validate a rig config's ``[world]`` table (absent: ideal); `preset` replaces the table's preset (the demo's
    ``--world``). Errors name the key, ``world.<key>``."""
    body = raw if raw is not None else {}
    if preset is not None:
        if preset not in PRESETS:
            raise ConfigError("--world", preset, f"must be one of {', '.join(PRESETS)}")
        body = {**body, "preset": preset} if isinstance(body, dict) else body
    return parse(WorldSettings, body, "world")
