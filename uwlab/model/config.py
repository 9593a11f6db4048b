"""The design configuration: its schema (one pydantic model per section), overrides and loading.

A design config is TOML with sections [spectral], [light], [water], [target], [housing], [lens], [sensor],
[operation], [model] and an optional array of [[lights]]. Every key carries its unit in its name and its meaning in
its field's description.

[model] kind selects the image-formation chain: ``paper`` (the default) is the paper's chain, which ignores every
key marked "extended model" below; ``extended`` (`uwlab.model.extended`) places the lights (the [[lights]] array,
else `light.separation_m`, else the paper's distance and incidence), gives them a beam profile, renders the target
pixel by pixel (a finite board with a surround), adds the water's veiling light (backscatter) and mechanical
vignetting. Numeric keys
that `uwlab design --grid` can vary are `Grid` quantities: a number or a numpy array (an open mesh), validated
element-wise. Physical plausibility limits (`uwlab.model.schema`) refuse values in a wrong unit. Errors are
`ConfigError`s naming ``section.key`` and the offending value.

>>> validate({"light": {"luminous_flux_lm": 25000, "beam_half_angle_deg": 40}, "water": {"type": "jerlov-I"},
...           "target": {"reflectance": 0.2}, "lens": {"focal_length_mm": 8, "f_number": 2.8},
...           "sensor": {"profile": "imx250m"}, "operation": {"altitude_m": 2}})["lens"]
{'focal_length_mm': 8.0, 'f_number': 2.8, 'transmittance': 1.0, 'min_focus_distance_m': None,
 'mechanical_vignetting': 0.0}
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import BeforeValidator, Field, model_validator

from uwlab.errors import ConfigError
from uwlab.model.data import read_toml
from uwlab.model.scattering import PhaseFunction
from uwlab.model.schema import (
    BitDepth,
    BlurPx,
    CircleOfConfusionMm,
    DistanceM,
    ExposureS,
    FNumber,
    FocalLengthMm,
    Fraction,
    GainDb,
    Grid,
    HalfAngleDeg,
    HousingMm,
    IncidenceDeg,
    LuminousFluxLm,
    NonEmptyText,
    PositionM,
    RefractiveIndex,
    ScatteringPerM,
    Schema,
    SpectralStepNm,
    SpeedMS,
    Transmittance,
    WavelengthNm,
    at_most_one,
    invalid,
    number_or,
    parse,
    limits,
)

# Light count: one to a thousand lights of the same kind.
LightCount = Annotated[int, limits(1, 1000, "lights", hint="", integer=True)]
# A factor on the tabulated beam attenuation c(λ): 0 (clear) to 100 times the water type's.
AttenuationScale = Annotated[float, limits(0.0, 100.0, "", hint="a factor on the water type's attenuation")]
# Image overlap between frames along the motion: a fraction below 1 (1 would need an infinite framerate).
Overlap = Annotated[float, limits(0.0, 1.0, "", hint="a fraction, not a percentage", hi_open=True)]
NAME_OR_FILE = "must be a number or a name or file path"
# A port's transmittance: a fraction, or "fresnel" (computed from the indices).
PortTransmittance = Annotated[Grid[Transmittance] | Literal["fresnel"], number_or('must be a number or "fresnel"')]
# The design's exposure: a time, or "max-blur" (the longest within the blur limit).
ExposureOrMaxBlur = Annotated[Grid[ExposureS] | Literal["max-blur"], number_or('must be a number or "max-blur"')]
# A flat window's thickness: 0 (the thin window of the paraxial rule) to 200 mm.
WindowMm = Annotated[float, limits(0.0, 200.0, "mm")]
# Entrance pupil → inner face of a flat window: 0 to 1000 mm.
AirGapMm = Annotated[float, limits(0.0, 1000.0, "mm")]
# Tilt of a flat window's normal from the optical axis: ±45°.
TiltDeg = Annotated[float, limits(-45.0, 45.0, "deg", hint="")]
# The entrance pupil's offset from a dome's centre: ±100 mm per axis (and inside the dome, `Housing`).
DecenterMm = Annotated[float, limits(-100.0, 100.0, "mm")]


def _comma_list(value):
    """``"1,0,-2"`` (a `--set` value that is not TOML) as a list of numbers; anything else unchanged."""
    if isinstance(value, str):
        try:
            return [float(v) for v in value.split(",")]
        except ValueError:
            return value
    return value


Vector2Deg = Annotated[list[TiltDeg], Field(min_length=2, max_length=2), BeforeValidator(_comma_list)]
Vector3Mm = Annotated[list[DecenterMm], Field(min_length=3, max_length=3), BeforeValidator(_comma_list)]
# Spectral exponent of the particles' scattering, b ∝ λ^−γ: 0 (large particles) to 4 (Rayleigh).
ScatteringExponent = Annotated[float, limits(0.0, 4.0, "", hint="")]
BeamModel = Literal["cone", "disk", "cos-power"]
BEAM_MODEL = (
    "cone: uniform intensity in the beam; disk: flux spread over the beam's footprint; cos-power (extended "
    "model; the paper model takes it as a cone): I ∝ cos^m ψ with half the peak intensity at the half-angle"
)


def _section(model):
    """A section field: absent in the file means all its defaults (its required keys are then reported)."""
    return Field(default={}, validate_default=True, description=model.__doc__.splitlines()[0])


class Spectral(Schema):
    """The wavelength grid every spectrum is sampled on [nm]."""

    start_nm: WavelengthNm = Field(380.0, description="first wavelength of the grid [nm]")
    stop_nm: WavelengthNm = Field(780.0, description="last wavelength of the grid [nm]")
    step_nm: SpectralStepNm = Field(1.0, description="wavelength step [nm]")

    @model_validator(mode="after")
    def _ordered(self):
        if self.stop_nm <= self.start_nm:
            raise invalid("stop_nm", self.stop_nm, "must exceed start_nm")
        return self


class LightSection(Schema):
    """The artificial light(s): spectrum, flux, beam and placement."""

    spectrum: NonEmptyText = Field("generic-led", description="relative spectrum: a named spectrum or a CSV file")
    luminous_flux_lm: Grid[LuminousFluxLm] = Field(description="rated luminous flux of one light [lm]")
    beam_half_angle_deg: Grid[HalfAngleDeg] | None = Field(
        None, description="beam half-angle in water [deg] (give this or beam_half_angle_in_air_deg)"
    )
    beam_half_angle_in_air_deg: Grid[HalfAngleDeg] | None = Field(
        None, description="beam half-angle as specified in air [deg], refracted into the water by the port"
    )
    beam_model: BeamModel = Field("cone", description=BEAM_MODEL)
    count: Grid[LightCount] = Field(1, description="number of identical lights")
    distance_m: Grid[DistanceM] | None = Field(None, description="light → target distance [m] (default: the altitude)")
    incidence_deg: Grid[IncidenceDeg] = Field(0.0, description="angle of incidence of the light on the target [deg]")
    separation_m: Grid[DistanceM] | None = Field(
        None,
        description="extended model: the lights' distance from the optical axis [m], `count` lights spread "
        "evenly around it from above the camera, in the camera's plane",
    )
    aim: Literal["target", "parallel"] = Field(
        "target",
        description="extended model: lights placed by separation_m aim at the target's centre or along "
        "the optical axis",
    )

    @model_validator(mode="after")
    def _one_beam_angle(self):
        if (self.beam_half_angle_deg is None) == (self.beam_half_angle_in_air_deg is None):
            raise invalid(
                "beam_half_angle_deg",
                self.beam_half_angle_deg,
                "give exactly one of beam_half_angle_deg (in water) and beam_half_angle_in_air_deg",
            )
        return self


class LightPlacement(Schema):
    """Extended model: one light of the [[lights]] array, placed in the camera frame (x right, y down, z along the
    optical axis from the camera's port) [m]; unset beam keys are [light]'s."""

    name: NonEmptyText | None = Field(
        None, description="the light's name: the sweep plan's [[lights]] table of this name drives it"
    )
    position_m: tuple[PositionM, PositionM, PositionM] = Field(description="the light's position [x, y, z] [m]")
    aim_m: tuple[PositionM, PositionM, PositionM] | None = Field(
        None, description="a point the light is aimed at [m] (default: along the optical axis)"
    )
    luminous_flux_lm: LuminousFluxLm | None = Field(None, description="rated luminous flux [lm]")
    beam_half_angle_deg: HalfAngleDeg | None = Field(None, description="beam half-angle in water [deg]")
    beam_half_angle_in_air_deg: HalfAngleDeg | None = Field(None, description="beam half-angle in air [deg]")
    beam_model: BeamModel | None = Field(None, description=BEAM_MODEL)
    transmittance: Transmittance = Field(
        1.0, description="fraction of the flux entering the water, e.g. through a window between light and water"
    )

    @model_validator(mode="after")
    def _one_beam_angle(self):
        return at_most_one(self, "beam_half_angle_deg", "beam_half_angle_in_air_deg")


class Water(Schema):
    """The water: its optical type, a scale on its attenuation and suspended particles."""

    type: NonEmptyText = Field(
        description="water type (pure-fresh, jerlov-I … jerlov-9C, jerlov-IB … jerlov-5C-williamson2022) or a CSV file"
    )
    attenuation_scale: Grid[AttenuationScale] = Field(1.0, description="factor on the beam attenuation c(λ)")
    particle_scattering_per_m: ScatteringPerM = Field(
        0.0,
        description="scattering coefficient b_p(550 nm) of added particles [1/m]: adds to the attenuation; "
        "extended model: also veiling light",
    )
    particle_scattering_exponent: ScatteringExponent = Field(1.0, description="γ of b_p(λ) = b_p(550) (550/λ)^γ")
    particle_phase_function: PhaseFunction = Field(
        "fournier-forand", description="particles' phase function (fournier-forand: Petzold's average)"
    )


class Target(Schema):
    """The Lambertian target (seafloor, test board)."""

    reflectance: Annotated[Grid[Fraction] | NonEmptyText, number_or(NAME_OR_FILE)] = Field(
        description="diffuse reflectance: a fraction, a named material or a CSV file"
    )
    board_size_m: tuple[DistanceM, DistanceM] | None = Field(
        None,
        description="extended model: the target is a board [x, y] [m] centred on the axis (default: it fills the view)",
    )
    surround_reflectance: Fraction = Field(0.0, description="extended model: reflectance around the board")


class Housing(Schema):
    """The camera housing's port and the refractive indices."""

    port: Literal["flat", "dome"] = Field("flat", description="port shape")
    water_index: Grid[RefractiveIndex] = Field(1.333, description="refractive index of the water")
    port_index: Grid[RefractiveIndex] = Field(1.49, description="refractive index of the port material")
    port_transmittance: PortTransmittance = Field(
        "fresnel", description='port transmittance: a fraction, or "fresnel" (two interfaces at normal incidence)'
    )
    dome_radius_mm: Grid[HousingMm] | None = Field(None, description="dome outer radius [mm] (dome ports)")
    dome_thickness_mm: Grid[HousingMm] | None = Field(None, description="dome wall thickness [mm] (dome ports)")
    dome_decenter_mm: Vector3Mm = Field(
        [0.0, 0.0, 0.0],
        description="[x, y, z] of the entrance pupil from the dome's centre, camera axes "
        "(x right, y down, z forward) [mm] (dome ports; `uwlab port`)",
    )
    flat_thickness_mm: Grid[WindowMm] = Field(0.0, description="flat window thickness [mm] (0: a thin window)")
    flat_air_gap_mm: Grid[AirGapMm] = Field(
        0.0, description="entrance pupil → inner face of the flat window, along its normal [mm]"
    )
    flat_tilt_deg: Vector2Deg = Field(
        [0.0, 0.0],
        description="[x, y] angles of the flat window's normal from the optical axis in the x–z and "
        "y–z planes [deg] (`uwlab port`)",
    )

    @model_validator(mode="after")
    def _dome(self):
        if self.port == "dome":
            for key in ("dome_radius_mm", "dome_thickness_mm"):
                if getattr(self, key) is None:
                    raise invalid(key, None, "required for a dome port")
            if np.any(np.asarray(self.dome_thickness_mm) >= np.asarray(self.dome_radius_mm)):
                raise invalid("dome_thickness_mm", self.dome_thickness_mm, "must be less than dome_radius_mm")
            inner = np.asarray(self.dome_radius_mm) - np.asarray(self.dome_thickness_mm)
            if np.any(np.linalg.norm(self.dome_decenter_mm) >= 0.5 * inner):
                raise invalid(
                    "dome_decenter_mm",
                    list(self.dome_decenter_mm),
                    "must be well inside the dome (less than half its inner radius)",
                )
        return self


class Lens(Schema):
    """The lens: focal length, aperture and transmittance."""

    focal_length_mm: Grid[FocalLengthMm] = Field(description="focal length (in air) [mm]")
    f_number: Grid[FNumber] = Field(description="f-number N = f / D")
    transmittance: Annotated[Grid[Transmittance] | NonEmptyText, number_or(NAME_OR_FILE)] = Field(
        1.0, description="lens transmittance: a fraction or a CSV file"
    )
    min_focus_distance_m: Grid[DistanceM] | None = Field(
        None, description="the lens's closest focus [m] (for the close-up lens of the focusing aids)"
    )
    mechanical_vignetting: Grid[Fraction] = Field(
        0.0, description="extended model: light lost at the image corner beyond cos⁴ (falls off as (r/r_corner)⁴)"
    )


class Sensor(Schema):
    """The image sensor and its settings."""

    profile: NonEmptyText = Field(description="sensor profile: a name in configs/sensors or a TOML file")
    gain_db: Grid[GainDb] = Field(0.0, description="analog gain [dB]")
    bit_depth: Grid[BitDepth] | None = Field(None, description="output bit depth [bit] (default: the profile's)")
    channel: Literal["combined", "red", "green", "blue"] = Field(
        "combined", description="colour channel of a colour sensor"
    )
    characterised: NonEmptyText | None = Field(
        None,
        description="this camera as characterised by `uwlab emva characterize` (its profile TOML or output "
        "folder): a fit takes its measured response curve (uwlab fit --sensor)",
    )


class Operation(Schema):
    """How the camera is used: altitude, speed, exposure and depth-of-field needs."""

    altitude_m: Grid[DistanceM] = Field(description="camera → target distance [m]")
    speed_m_s: Grid[SpeedMS] = Field(0.0, description="vehicle speed over the target [m/s]")
    overlap: Grid[Overlap] = Field(0.0, description="overlap between consecutive frames along the motion")
    max_blur_px: Grid[BlurPx] = Field(1.0, description="largest acceptable motion blur [px]")
    exposure_s: Annotated[Grid[ExposureS] | Literal["max-blur"], number_or('must be a number or "max-blur"')] = Field(
        "max-blur", description='exposure time [s], or "max-blur": the longest exposure within max_blur_px'
    )
    motion_axis: Literal["x", "y"] = Field("y", description="sensor axis along the motion")
    min_dof_m: Grid[DistanceM] | None = Field(None, description="required depth of field [m]")
    circle_of_confusion_mm: Grid[CircleOfConfusionMm] | None = Field(
        None, description="acceptable circle of confusion on the sensor [mm] (default: the sensor diagonal / 1500)"
    )


class Model(Schema):
    """The image-formation chain."""

    kind: Literal["paper", "extended"] = Field(
        "paper", description="paper: the paper's chain; extended: `uwlab.model.extended`"
    )


class DesignConfig(Schema):
    """A design config: one table per section, and the extended model's [[lights]]."""

    spectral: Spectral = _section(Spectral)
    light: LightSection = _section(LightSection)
    water: Water = _section(Water)
    target: Target = _section(Target)
    housing: Housing = _section(Housing)
    lens: Lens = _section(Lens)
    sensor: Sensor = _section(Sensor)
    operation: Operation = _section(Operation)
    model: Model = _section(Model)
    lights: list[LightPlacement] = Field([], description=(LightPlacement.__doc__ or "").splitlines()[0])


def validate(raw: dict) -> dict:
    """Validate a raw config against `DesignConfig`, fill defaults; returns {section: {key: value}} and, for
    ``lights``, a list of such tables."""
    config = parse(DesignConfig, raw)
    return {name: [dict(light) for light in section] if name == "lights" else dict(section) for name, section in config}


def parse_value(text: str):
    """A `--set` value: TOML syntax if it parses (numbers, booleans, quoted strings), else a bare string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_grid_values(key: str, text: str) -> list:
    """A `--grid` axis: ``START:STOP:STEP`` (inclusive of stop, at most 10⁷ values) or a comma list of `--set`
    values (TOML or bare words); a bad or unbounded range raises `ConfigError` naming ``key``.

    >>> parse_grid_values("lens.f_number", "2:4:1")
    [2.0, 3.0, 4.0]
    """
    if text.count(":") == 2:
        try:
            start, stop, step = (float(x) for x in text.split(":"))
        except ValueError:
            raise ConfigError(key, text, "grid range must be START:STOP:STEP numbers") from None
        if not all(math.isfinite(x) for x in (start, stop, step)):
            raise ConfigError(key, text, "grid range must be finite START:STOP:STEP numbers")
        if step <= 0 or stop < start:
            raise ConfigError(key, text, "grid range needs step > 0 and stop >= start")
        steps = (stop - start) / step  # inf when the span or the ratio overflows (1:1e308:1e-308)
        count = int(math.floor(steps + 1e-9)) + 1 if steps < 10_000_000 else math.inf
        if count > 10_000_000:
            raise ConfigError(key, text, f"{steps + 1:.4g} values in one axis is too many (at most 10⁷)")
        return (start + step * np.arange(count)).tolist()
    values = [parse_value(v.strip()) for v in text.split(",") if v.strip()]
    if not values:
        raise ConfigError(key, text, "no grid values")
    return values


def split_assignment(text: str, option: str) -> tuple[str, str]:
    """``SECTION.KEY=VALUE`` (a `--set` or `--grid` argument) → (key, value text)."""
    key, eq, value = text.partition("=")
    if not eq or not key:
        raise ConfigError(option, text, "expected SECTION.KEY=VALUE")
    return key.strip(), value.strip()


def apply_override(raw: dict, dotted: str, value) -> None:
    """Set raw[section][key] = value for a ``section.key`` path (unknown keys fail later, in `validate`)."""
    section, dot, key = dotted.partition(".")
    if not dot or not section or not key or "." in key:
        raise ConfigError(dotted, value, "expected section.key")
    body = raw.setdefault(section, {})
    if not isinstance(body, dict):
        raise ConfigError(section, body, "must be a table")
    body[key] = value


SIMULATION_SECTIONS = ("sim", "world")


def design_sections(raw: dict) -> dict:
    """The design part of a rig config: every section but the simulated rig's (``[sim]``, ``[world]``, read by
    `uwlab.sim`). A real rig's config has none of those; a simulated rig's is its design plus them.

    >>> design_sections({"lens": {"f_number": 2.8}, "sim": {"seed": 1}, "world": {"preset": "tank"}})
    {'lens': {'f_number': 2.8}}
    """
    return {k: v for k, v in raw.items() if k not in SIMULATION_SECTIONS}


def rate_design_sections(raw: dict) -> dict:
    """The design sections of a rig config as the design of its rates: without ``operation.exposure_s``. A rig's
    design gives electron rates [e⁻/s]; the exposure is each measured point's own setting (in µs, parsed and checked
    against the sensor once, where the sweep plan is read), which the camera applies and the forward model
    multiplies by. The design's own exposure then keeps its default (the blur limit), which no check can refuse.

    >>> rate_design_sections({"operation": {"altitude_m": 1, "exposure_s": 2e-4}, "world": {}})
    {'operation': {'altitude_m': 1}}
    """
    sections = design_sections(raw)
    operation = {k: v for k, v in sections.get("operation", {}).items() if k != "exposure_s"}
    return {**sections, **({"operation": operation} if "operation" in sections else {})}


def load_raw(path: str | Path) -> dict:
    return read_toml(Path(path), "config")
