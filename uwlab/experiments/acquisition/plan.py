"""Sweep plans: a TOML file naming the rig, its geometry and one or more ``[[sweep]]`` tables.

Schema (docs/sweeps.md has a commented example). Top level:

- ``name``, ``description`` (text); ``rig`` (required): a design config (`uwlab design` sections, plus the
  simulated rig's ``[sim]``) or an EMVA 1288 bench (a ``[bench]`` table, `uwlab.model.bench`), relative to the plan
  file; ``[geometry]``: design sections overriding the rig for
  every sweep (``[geometry.light] distance_m = 1.2``);
- ``[camera]``: ``backend``, ``id``, ``pixel_format``, ``bayer`` (the colour filter layout the camera must deliver,
  ``"RG"``, ``"GR"``, ``"GB"`` or ``"BG"``: a device whose PixelFormat is another layout or monochrome is refused
  before anything is recorded), ``window`` = [x, y, w, h] (device ROI), ``timeout_s``,
  ``reconnect_attempts`` and ``outage_limit_s`` (the reconnect bounds of `uwlab.drivers.camera.Policy`);
- ``[[lights]]``: one table per light, each its own instrument: ``name`` (default ``light<i>``), ``instrument`` (a
  definition in configs/instruments/ or a file, `uwlab.drivers.instruments`), ``resource`` (its VISA resource),
  ``visa_library`` (PyVISA's: ``@py`` by default, ``PATH.yaml@sim`` for pyvisa-sim, relative to the plan),
  ``max_current_a`` (the rig's maximum drive, never above the definition's; a request beyond it is refused before
  anything is sent) and ``level`` (what it holds while a sweep dims another light, default 1). A sweep's ``light``
  names the light its level and light-level values apply to (default: the first);
- ``[instruments]``: ``spectrometer_port``, ``reopen_s`` (how long a vanished port may take to come back, default
  5 s) (real hardware; ``--sim`` replaces them); ``light_port`` and ``protocol`` (a ``uwlab-ascii`` light on a
  serial port) still work for one release, with a one-line deprecation notice (`Plan.notices`); instead of
  ``spectrometer_port``, ``[instruments.seabreeze_spectrometer]`` (``instrument``, ``resource``, ``calibration``,
  ``area_cm2``): a USB spectrometer through python-seabreeze (docs/spectrometers.md);
- ``[defaults]``: any sweep key, applied to every sweep unless the sweep sets it.

Each ``[[sweep]]``: ``id`` (unique), ``kind`` (exposure | aperture | gain | light-level | dark | geometry), ``values``
(a list, or ``{start, stop, num, spacing = "linear" | "log"}``: exposure_us, f-number, gain_db or light level;
a dark sweep steps exposure_us with the light off), ``frames_per_point`` (≥ 2), ``settle_s``, ``dark``
("point": dark frames at every point, "block": once per sweep, only when camera settings stay fixed, "none"),
``dark_frames`` (≥ 2), ``spectrometer`` (positions read at each point: "target", "camera", "sensor"; the first gives the
point's ``irradiance_w_m2``), ``spectrometer_integration_ms``, ``spectrometer_averaging``, ``roi`` ([x, y, w, h]
within the acquired image, or "aruco"), ``aruco_dictionary``, ``saturation_threshold`` (fraction of ROI pixels
at the camera's clip level above which a point is flagged; `uwlab.experiments.saturation`),
``lens`` ("none", or ``{focal_length_mm, f_number, f_number_range = [lo, hi], manual = true}``), ``sensor`` (the
sensor profile: sets the rig's ``sensor.profile``; the simulated camera uses it), ``camera`` (a table overriding
``[camera]``), the fixed settings ``exposure_us``, ``gain_db``, ``black_level_dn``, ``light_level``,
``save_frames`` (TIFFs under ``frames/``) and ``geometry`` (design overrides for this sweep only).

A geometry sweep (``kind = "geometry"``, docs/sweeps.md) measures a slanted edge's e-SFR at each point: ``step``
names what its values step (``lens_focus_m``: the lens focus setting, the air-equivalent distance from the pupil;
``target_distance_m``: the target's distance from the pupil; ``f_number``; ``exposure_us`` with the target moving at
the rig's ``operation.speed_m_s``, refused when it is 0); ``lens_focus_m`` and ``target_distance_m`` fix the
settings not stepped (defaults: the target's image through the port, `uwlab.model.focus.target_image_distance_m`,
and the rig's ``operation.altitude_m``); ``edge_roi`` ([x, y, w, h] within the image; default: found). It needs a
lens and a tank rig; the geometry keys on another kind of sweep are refused.

No lens: the resolved rig of a "no lens" sweep carries the bare sensor's f-number and transmittance
(`uwlab.model.optics.NO_LENS`); its rows have null focal length and f-number.

Unknown keys and impossible values raise `ConfigError` naming the key (``sweep.<id>.<key>``).
"""

from __future__ import annotations

import copy
import hashlib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from pydantic import AfterValidator, BeforeValidator, ConfigDict, Field, StrictBool, field_validator, model_validator
from pydantic_core import PydanticCustomError

from uwlab.drivers.camera import BACKENDS, Policy
from uwlab.drivers.camera.pixels import PIXEL_FORMATS, BayerLayout
from uwlab.drivers.instruments import load_any_light_definition
from uwlab.drivers.instruments.definition import LightRig, SerialLightDefinition
from uwlab.drivers.ocean_insight.definition import CollectionAreaCm2
from uwlab.drivers.serial import PROTOCOLS
from uwlab.drivers.serial.base import Averaging, IntegrationMs
from uwlab.model.config import SIMULATION_SECTIONS, rate_design_sections
from uwlab.errors import ConfigError
from uwlab.experiments.dataset import SweepKind
from uwlab.experiments.saturation import POINT_SATURATED_FRACTION
from uwlab.jsonable import to_jsonable
from uwlab.model.config import apply_override
from uwlab.model.data import MAX_TOML_BYTES, read_bytes, read_toml, resolve_path
from uwlab.model.bench import Bench, build_bench, is_bench
from uwlab.model.build import build_design
from uwlab.model.design import Design
from uwlab.model.evaluation import SpectrometerPosition
from uwlab.model.optics import NO_LENS, LensSetting
from uwlab.model.sensor import SensorProfile
from uwlab.model.schema import (
    DistanceM,
    DurationS,
    ExposureUs,
    FNumber,
    FocalLengthMm,
    Fraction,
    FrameCount,
    GainDb,
    NonEmptyText,
    Number,
    Schema,
    Text,
    at_most_one,
    check,
    either,
    invalid,
    is_list,
    is_table,
    is_text,
    limits_of,
    parse,
    limits,
    within,
)

DarkMode = Literal["point", "block", "none"]
# What a geometry sweep steps: the lens focus setting, the target's distance, the f-number, or the exposure (the
# target moving at the rig's ``operation.speed_m_s``).
GeometryStep = Literal["lens_focus_m", "target_distance_m", "f_number", "exposure_us"]
GEOMETRY_KEYS = ("step", "lens_focus_m", "target_distance_m", "edge_roi")
MAX_POINTS = 10000
# Pixel coordinates of a window or ROI: offsets from 0, sizes from 2 (a variance needs two pixels).
OffsetPx = Annotated[int, limits(0, 100000, "px", hint="", integer=True)]
SizePx = Annotated[int, limits(2, 100000, "px", hint="", integer=True)]
TimeoutS = Annotated[float, limits(0.01, 600.0, "s")]
OutageS = Annotated[float, limits(0.1, 86400.0, "s")]
Attempts = Annotated[int, limits(0, 1000, "attempts", hint="", integer=True)]
ReopenS = Annotated[float, limits(0.0, 3600.0, "s")]
LEGACY_LIGHT_KEYS = ("light_port", "protocol")
DigitalNumber = Annotated[float, limits(0.0, 2.0**32, "DN", hint="")]
PointCount = Annotated[int, limits(1, MAX_POINTS, "points", hint="", integer=True)]
if TYPE_CHECKING:  # names registered at run time (the installed camera backends, pixel formats, serial protocols)
    BackendName = str
    PixelFormatName = str
    ProtocolName = str
else:
    BackendName = Literal[tuple(BACKENDS)]
    PixelFormatName = Literal[tuple(PIXEL_FORMATS)]
    ProtocolName = Literal[PROTOCOLS]


def _four(value):
    if isinstance(value, (list, tuple)) and len(value) != 4:
        raise PydanticCustomError("rectangle", "must be [x, y, width, height] in pixels")
    return value


Rectangle = Annotated[tuple[OffsetPx, OffsetPx, SizePx, SizePx], BeforeValidator(_four)]


def _aruco(name: str) -> str:
    import cv2

    if not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
        raise PydanticCustomError("aruco", "must name a cv2.aruco predefined dictionary, e.g. DICT_4X4_50")
    return name


class CameraSpec(Schema):
    """[camera], and a sweep's ``camera`` table overriding it."""

    model_config = ConfigDict(populate_by_name=True)

    backend: BackendName = Field("sim", description="camera backend")
    device_id: NonEmptyText | None = Field(None, alias="id", description="device id (default: the first found)")
    pixel_format: PixelFormatName | None = Field(None, description="pixel format (default: the camera's)")
    bayer: BayerLayout | None = Field(
        None, description="colour filter layout the camera must deliver (refused when its PixelFormat differs)"
    )
    window: Rectangle | None = Field(None, description="device region of interest [x, y, width, height] [px]")
    timeout_s: TimeoutS = Field(5.0, description="per-frame acquisition timeout [s]")
    reconnect_attempts: Attempts = Field(Policy.reconnect_attempts, description="reconnect attempts per outage")
    outage_limit_s: OutageS = Field(Policy.outage_limit_s, description="longest camera outage ridden out [s]")

    def policy(self) -> Policy:
        """The camera's fault-handling bounds (docs/cameras.md, "Reconnect policy")."""
        return Policy(
            timeout_s=self.timeout_s, reconnect_attempts=self.reconnect_attempts, outage_limit_s=self.outage_limit_s
        )


class SeabreezeSpectrometerTable(Schema):
    """[instruments.seabreeze_spectrometer]: a USB spectrometer by instrument definition (docs/spectrometers.md)."""

    instrument: NonEmptyText = Field("ocean-insight", description="definition in configs/instruments/")
    resource: NonEmptyText | None = Field(None, description="serial number (default: the first found)")
    calibration: NonEmptyText = Field(
        description="calibration file (wavelength_nm, uJ_per_count), relative to the plan"
    )
    area_cm2: CollectionAreaCm2 | None = Field(None, description="collection area [cm²] (default: the definition's)")


class InstrumentsSection(Schema):
    """[instruments]: the serial instruments of the real rig (``--sim`` replaces them)."""

    light_port: NonEmptyText | None = Field(None, description="serial port of the light controller")
    spectrometer_port: NonEmptyText | None = Field(None, description="serial port of the spectrometer")
    seabreeze_spectrometer: SeabreezeSpectrometerTable | None = Field(
        None, description="a USB spectrometer through python-seabreeze instead of spectrometer_port"
    )
    protocol: ProtocolName = Field(PROTOCOLS[0], description="instrument protocol")
    reopen_s: ReopenS = Field(5.0, description="how long a vanished serial port may take to come back [s]")

    @model_validator(mode="after")
    def _one_spectrometer(self):
        return at_most_one(self, "spectrometer_port", "seabreeze_spectrometer")


class LightTable(LightRig):
    """A ``[[lights]]`` table: one light, its instrument definition and VISA resource, and what the rig says of its
    LED (`LightRig`: ``max_current_a``, ``forward_voltage_v``, ``identity_contains``)."""

    name: NonEmptyText | None = Field(None, description="the light's name (default light<i>)")
    instrument: NonEmptyText = Field(description="instrument definition: a name in configs/instruments/ or a file")
    resource: NonEmptyText = Field(description="VISA resource (uwlab devices lists them)")
    visa_library: NonEmptyText | None = Field(None, description="PyVISA library: @py (default), PATH.yaml@sim")
    level: Fraction = Field(1.0, description="the level it holds while a sweep dims another light")


class LensTable(Schema):
    """A sweep's ``lens`` table."""

    focal_length_mm: FocalLengthMm = Field(description="focal length [mm]")
    f_number: FNumber = Field(description="f-number set for the sweep")
    f_number_range: tuple[FNumber, FNumber] | None = Field(None, description="the lens's [lowest, highest] f-number")
    manual: StrictBool = Field(True, description="the aperture is set by hand (the operator is asked)")

    @model_validator(mode="after")
    def _in_range(self):
        if self.f_number_range is not None:
            lo, hi = self.f_number_range
            if lo > hi:
                raise invalid("f_number_range", list(self.f_number_range), "must be [lowest, highest]")
            if not lo <= self.f_number <= hi:
                raise invalid("f_number", self.f_number, f"outside the lens's range [{lo:g}, {hi:g}]")
        return self

    def setting(self) -> LensSetting:
        return LensSetting(self.focal_length_mm, self.f_number, self.f_number_range, self.manual)


class ValueRange(Schema):
    """A sweep's ``values`` as a range: ``num`` values from ``start`` to ``stop`` (both included)."""

    start: Number = Field(description="first value")
    stop: Number = Field(description="last value")
    num: PointCount = Field(description="number of values")
    spacing: Literal["linear", "log"] = Field("linear", description="linear or logarithmic steps")

    @model_validator(mode="after")
    def _log_positive(self):
        if self.spacing == "log" and (self.start <= 0 or self.stop <= 0):
            raise invalid("start", self.start, "log spacing needs positive start and stop")
        return self

    def expand(self) -> tuple[float, ...]:
        space = np.geomspace if self.spacing == "log" else np.linspace
        return tuple(float(v) for v in space(self.start, self.stop, self.num))


SweepValues = Annotated[
    Annotated[list[Number], Field(min_length=1, max_length=MAX_POINTS)] | ValueRange,
    either("must be a list of numbers or {start, stop, num, spacing}", is_list, is_table),
]
LensSpec = Annotated[
    Literal["none"] | LensTable,
    either('must be "none" or {focal_length_mm, f_number, f_number_range, manual}', is_text, is_table),
]
Roi = Annotated[
    Literal["aruco"] | Rectangle, either('must be [x, y, width, height] in pixels or "aruco"', is_text, is_list)
]
DesignSections = dict[str, dict[str, Any]]


class SweepTable(Schema):
    """A ``[[sweep]]`` table (with the plan's [defaults] filled in), as written."""

    id: NonEmptyText = Field(description="unique name of the sweep")
    kind: SweepKind = Field(description="what the sweep steps")
    values: SweepValues = Field(description="exposure_us, f-number, gain_db or light level of each point")
    frames_per_point: FrameCount = Field(2, description="frames averaged per point")
    settle_s: DurationS = Field(0.0, description="wait after changing the light [s]")
    dark: DarkMode = Field("point", description="dark frames at every point, once per sweep, or none")
    dark_frames: FrameCount | None = Field(None, description="dark frames per dark point (default: frames_per_point)")
    spectrometer: list[SpectrometerPosition] = Field([], description="positions read at each point")
    spectrometer_integration_ms: IntegrationMs = Field(10.0, description="spectrometer integration time [ms]")
    spectrometer_averaging: Averaging = Field(1, description="spectra averaged per reading")
    roi: Roi | None = Field(None, description='[x, y, width, height] within the image [px], or "aruco"')
    aruco_dictionary: Annotated[NonEmptyText, AfterValidator(_aruco)] = Field(
        "DICT_4X4_50", description="cv2.aruco dictionary of the ROI markers"
    )
    saturation_threshold: Fraction = Field(
        POINT_SATURATED_FRACTION, description="fraction of saturated ROI pixels flagging a point"
    )
    lens: LensSpec | None = Field(None, description='"none", or the lens table (default: the rig\'s lens)')
    sensor: NonEmptyText | None = Field(None, description="sensor profile (sets the rig's sensor.profile)")
    camera: dict[str, Any] = Field({}, description="keys overriding [camera]")
    exposure_us: ExposureUs | None = Field(None, description="fixed exposure [µs] (default: the values' median)")
    gain_db: GainDb = Field(0.0, description="fixed gain [dB]")
    black_level_dn: DigitalNumber | None = Field(None, description="camera black level [DN]")
    light_level: Fraction = Field(1.0, description="fixed light level")
    light: NonEmptyText | None = Field(None, description="the [[lights]] name the level applies to (default: first)")
    save_frames: StrictBool = Field(False, description="write each point's frames as TIFF under frames/")
    geometry: DesignSections = Field({}, description="design sections overriding the rig for this sweep")
    step: GeometryStep | None = Field(None, description="what a geometry sweep steps (its values' unit)")
    lens_focus_m: DistanceM | None = Field(
        None,
        description="a geometry sweep's lens focus setting [m, air-equivalent, from the pupil] (default: the "
        "target's image)",
    )
    target_distance_m: DistanceM | None = Field(
        None, description="a geometry sweep's target distance from the pupil [m] (default: operation.altitude_m)"
    )
    edge_roi: Rectangle | None = Field(
        None, description="a geometry sweep's slanted edge [x, y, width, height] within the image (default: found)"
    )

    @model_validator(mode="after")
    def _geometry_keys(self):
        if self.kind == "geometry" and self.step is None:
            raise invalid("step", None, "a geometry sweep needs step = " + " | ".join(GeometryStep.__args__))
        if self.kind != "geometry":
            for key in GEOMETRY_KEYS:
                if getattr(self, key) is not None:
                    raise invalid(key, getattr(self, key), 'only for a kind = "geometry" sweep')
        return self

    @field_validator("spectrometer")
    @classmethod
    def _distinct(cls, value):
        if len(set(value)) != len(value):
            raise PydanticCustomError("distinct", "positions must be distinct")
        return value

    @field_validator("geometry")
    @classmethod
    def _no_sim(cls, value):
        return _design_sections(value)


def _design_sections(value: dict) -> dict:
    for section in SIMULATION_SECTIONS:
        if section in value:
            raise invalid(section, value[section], "the simulation settings belong to the rig, not the geometry")
    return value


class PlanFile(Schema):
    """A plan file's top level."""

    name: NonEmptyText | None = Field(None, description="plan name (default: the file name)")
    description: Text = Field("", description="what the plan measures")
    rig: NonEmptyText = Field(description="the rig's design config, relative to the plan (e.g. ../rigs/sim-tank.toml)")
    geometry: DesignSections = Field({}, description="design sections overriding the rig for every sweep")
    camera: CameraSpec = Field(CameraSpec(), description=CameraSpec.__doc__)
    instruments: InstrumentsSection = Field(InstrumentsSection(), description=InstrumentsSection.__doc__)
    lights: list[LightTable] = Field([], description=LightTable.__doc__)
    defaults: dict[str, Any] = Field({}, description="sweep keys applied to every sweep that does not set them")
    sweep: list[dict[str, Any]] = Field(min_length=1, description="the [[sweep]] tables")

    @field_validator("defaults")
    @classmethod
    def _sweep_keys(cls, value):
        allowed = [k for k in SweepTable.model_fields if k != "id"]
        for key in value:
            if key not in allowed:
                raise invalid(key, value[key], f"unknown key; allowed: {', '.join(allowed)}")
        return value

    @field_validator("geometry")
    @classmethod
    def _no_sim(cls, value):
        return _design_sections(value)


@dataclass(frozen=True)
class Point:
    """The settings of one point of a sweep (None: the sweep's fixed setting applies)."""

    index: int
    exposure_us: float
    gain_db: float
    f_number: float | None
    light_level: float
    light_on: bool
    lens_focus_m: float | None = None  # a geometry point's focus setting and target distance (else None)
    target_distance_m: float | None = None


@dataclass(frozen=True)
class SweepSpec:
    """One ``[[sweep]]`` resolved: its validated table (every setting as written, the plan's [defaults] filled in:
    each declared once, in `SweepTable`) and what is resolved from the table and the rig."""

    table: SweepTable
    values: tuple[float, ...]  # the table's values, a range expanded
    dark_frames: int  # the table's dark_frames, else its frames_per_point
    exposure_us: float  # the table's exposure_us, else an exposure or dark sweep's median value, else 1000 µs
    lens: LensSetting  # the table's lens, else the rig's
    sensor_profile: str  # the rig's sensor.profile (the table's sensor, if it sets one)
    camera: CameraSpec  # the plan's [camera] with the table's camera keys over it
    rig_raw: dict  # the rig config with the plan's and the sweep's geometry, its sensor and lens written in
    design: Design | Bench  # rig_raw validated: the design of its rates, or the EMVA 1288 bench
    lens_focus_m: float | None = None  # a geometry sweep's fixed focus setting and target distance (else None)
    target_distance_m: float | None = None

    def points(self) -> list[Point]:
        """Every point of the sweep, in order."""
        return [self._point(i, v) for i, v in enumerate(self.values)]

    def _point(self, index: int, value: float) -> Point:
        """The point stepping the setting of the sweep's kind to ``value``, the others at the sweep's fixed ones."""
        kind, step = self.table.kind, self.table.step
        geometry = kind == "geometry"
        return Point(
            index=index,
            exposure_us=value if kind in ("exposure", "dark") or step == "exposure_us" else self.exposure_us,
            gain_db=value if kind == "gain" else self.table.gain_db,
            f_number=value if kind == "aperture" or step == "f_number" else self.lens.f_number,
            light_level=value if kind == "light-level" else self.table.light_level,
            light_on=kind != "dark",
            lens_focus_m=value if step == "lens_focus_m" else self.lens_focus_m if geometry else None,
            target_distance_m=value if step == "target_distance_m" else self.target_distance_m if geometry else None,
        )


@dataclass(frozen=True)
class LightSpec:
    """One light of the plan (a ``[[lights]]`` table resolved: its name, ``visa_library`` path made absolute)."""

    name: str
    instrument: str
    resource: str
    visa_library: str | None
    max_current_a: float | None
    level: float
    placement: int | None = None  # the rig's [[lights]] placement it drives (None: the rig places none)
    forward_voltage_v: float | None = None  # its LED's maximum forward voltage (a CV/CC supply's compliance)
    identity_contains: tuple[str, ...] = ()  # words its *IDN? must contain besides the definition's


@dataclass(frozen=True)
class Plan:
    path: Path
    sha256: str
    raw: dict
    name: str
    rig_path: Path
    sweeps: tuple[SweepSpec, ...]
    instruments: InstrumentsSection
    lights: tuple[LightSpec, ...] = ()
    notices: tuple[str, ...] = ()  # one line each (deprecated keys), for the CLI to print

    def total_points(self) -> int:
        return sum(len(s.values) for s in self.sweeps)


def plan_sha256(path: str | Path) -> str:
    return hashlib.sha256(read_bytes(path, "plan", MAX_TOML_BYTES, "TOML")).hexdigest()


def load_plan(path: str | Path) -> Plan:
    """Read, validate and resolve a plan file (`ConfigError` naming the key on any problem)."""
    path = Path(path)
    raw = read_toml(path, "plan")
    return parse_plan(raw, path, plan_sha256(path))


def parse_plan(raw: dict, path: Path, sha256: str) -> Plan:
    plan = parse(PlanFile, raw)
    rig_path = resolve_path(plan.rig, path.resolve().parent)
    rig_raw = read_toml(rig_path, "rig")
    camera = raw.get("camera", {})
    sweeps = [
        _sweep({**plan.defaults, **body}, number, rig_raw, rig_path.parent, plan.geometry, camera)
        for number, body in enumerate(plan.sweep)
    ]
    ids = [s.table.id for s in sweeps]
    duplicated = sorted({i for i in ids if ids.count(i) > 1})
    if duplicated:
        raise ConfigError("sweep.id", duplicated[0], "sweep ids must be unique within the plan")
    lights = _placed(_lights(plan, path.resolve().parent), sweeps, rig_path)
    for sweep in sweeps:
        light = sweep.table.light
        if light is not None and light not in {spec.name for spec in lights}:
            known = ", ".join(spec.name for spec in lights) or "none: the plan has no [[lights]]"
            raise ConfigError(f"sweep.{sweep.table.id}.light", light, f"no such light; known: {known}")
    return Plan(
        path=path,
        sha256=sha256,
        raw=raw,
        name=plan.name or path.stem,
        rig_path=rig_path,
        sweeps=tuple(sweeps),
        instruments=plan.instruments,
        lights=lights,
        notices=_deprecations(raw),
    )


def _lights(plan: PlanFile, plan_dir: Path) -> tuple[LightSpec, ...]:
    """The plan's [[lights]], named (``light<i>`` by default, names unique), a relative ``PATH.yaml@sim`` library
    resolved against the plan's folder; refused beside the deprecated ``instruments.light_port``."""
    if plan.lights and plan.instruments.light_port is not None:
        raise ConfigError(
            "instruments.light_port", plan.instruments.light_port, "give either [[lights]] or light_port, not both"
        )
    lights: list[LightSpec] = []
    for index, table in enumerate(plan.lights):
        library = table.visa_library
        if library is not None and library.endswith("@sim") and len(library) > 4:
            library = f"{resolve_path(library[:-4], plan_dir)}@sim"
        _check_light_instrument(index, table)
        name = table.name or f"light{index}"
        if name in {light.name for light in lights}:
            raise ConfigError(f"lights[{index}].name", name, "light names must be unique within the plan")
        lights.append(
            LightSpec(
                name,
                table.instrument,
                table.resource,
                library,
                table.max_current_a,
                table.level,
                forward_voltage_v=table.forward_voltage_v,
                identity_contains=tuple(table.identity_contains),
            )
        )
    return tuple(lights)


def _placed(lights: tuple[LightSpec, ...], sweeps: list[SweepSpec], rig_path: Path) -> tuple[LightSpec, ...]:
    """Each plan light joined to the rig's placement it drives (the extended model's [[lights]] in the rig): by
    name where the rig names its placements, else in order, one instrument per placement. Every sweep's resolved
    rig must place the same lights. A rig without placements (the paper's ``light.count`` identical lights, lit
    together) joins none."""
    placements = [sweep.rig_raw.get("lights") or [] for sweep in sweeps]
    first = placements[0] if placements else []
    for sweep, placed in zip(sweeps, placements, strict=True):
        if [light.get("name") for light in placed] != [light.get("name") for light in first]:
            raise ConfigError(
                f"sweep.{sweep.table.id}.geometry.lights", len(placed), "every sweep must place the plan's lights alike"
            )
    if not lights or not first:
        return lights
    names = [light.get("name") for light in first]
    if any(name is not None for name in names):
        index = {name: i for i, name in enumerate(names)}
        for number, light in enumerate(lights):
            if light.name not in index:
                known = ", ".join(str(n) for n in names)
                raise ConfigError(f"lights[{number}].name", light.name, f"the rig {rig_path.name} places {known}")
        return tuple(replace(light, placement=index[light.name]) for light in lights)
    if len(lights) != len(first):
        raise ConfigError(
            "lights",
            len(lights),
            f"the rig {rig_path.name} places {len(first)} lights ([[lights]]): give one instrument per placement, "
            "in the same order (or name the placements)",
        )
    return tuple(replace(light, placement=number) for number, light in enumerate(lights))


def _check_light_instrument(index: int, table: LightTable) -> None:
    """The light's definition exists and is valid, and the rig's maximum is a current no higher than its own."""
    try:
        definition = load_any_light_definition(table.instrument)
    except ConfigError as exc:
        raise ConfigError(f"lights[{index}].{exc.key}", exc.value, exc.reason) from None
    limit = table.max_current_a
    if table.visa_library is not None and definition.adapter != "visa":
        raise ConfigError(f"lights[{index}].visa_library", table.visa_library, f"{table.instrument} is not on VISA")
    supply = not isinstance(definition, SerialLightDefinition) and definition.constant_current is not None
    if table.forward_voltage_v is not None and not supply:
        raise ConfigError(
            f"lights[{index}].forward_voltage_v",
            table.forward_voltage_v,
            f"{table.instrument} sets no voltage limit (no [constant_current] section)",
        )
    if table.identity_contains and isinstance(definition, SerialLightDefinition):
        raise ConfigError(f"lights[{index}].identity_contains", table.identity_contains, "applies to a VISA light")
    if limit is None:
        return
    if isinstance(definition, SerialLightDefinition) or definition.drive != "current_a":
        raise ConfigError(f"lights[{index}].max_current_a", limit, f"{table.instrument} drives {definition.drive}")
    if limit > definition.max_drive:
        raise ConfigError(
            f"lights[{index}].max_current_a",
            limit,
            f"above {table.instrument}'s own maximum {definition.max_drive:g} A",
        )


def _deprecations(raw: dict) -> tuple[str, ...]:
    """One line per deprecated key the plan uses (they keep working for one release)."""
    section = raw.get("instruments", {})
    used = [key for key in LEGACY_LIGHT_KEYS if isinstance(section, dict) and key in section]
    if not used:
        return ()
    keys = " and ".join(f"instruments.{key}" for key in used)
    return (
        f"deprecated: {keys} (a uwlab-ascii light on a serial port) will be removed in the next release; "
        "use [[lights]] with instrument and resource (docs/instruments.md)",
    )


def sweep_tables(raw: dict) -> dict[str, dict]:
    """``{sweep_id: its [[sweep]] table with the plan's [defaults] applied}`` of a parsed plan TOML (as stored in a
    dataset's metadata; its rig is not read)."""
    defaults = raw.get("defaults", {}) if isinstance(raw.get("defaults"), dict) else {}
    tables = raw.get("sweep", [])
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise ConfigError("sweep", tables, "must be a list of [[sweep]] tables")
    bodies = [{**defaults, **table} for table in tables]
    return {str(body.get("id", number)): body for number, body in enumerate(bodies)}


def point_counts(raw: dict) -> dict[str, int]:
    """``{sweep_id: number of points}`` of a parsed plan TOML (as stored in a dataset's metadata)."""
    return {
        sweep_id: len(expand_values(f"sweep.{sweep_id}.values", body.get("values")))
        for sweep_id, body in sweep_tables(raw).items()
    }


def expand_values(key: str, spec: Any) -> tuple[float, ...]:
    """A sweep's values: a non-empty list of numbers, or ``{start, stop, num, spacing}`` (both ends included)."""
    return _expand(check(SweepValues, spec, key))


def _expand(values: list[float] | ValueRange) -> tuple[float, ...]:
    return values.expand() if isinstance(values, ValueRange) else tuple(float(v) for v in values)


def _sweep(body: dict, number: int, rig_raw: dict, rig_dir: Path, geometry: dict, camera: dict) -> SweepSpec:
    sweep_id = body.get("id")
    prefix = f"sweep.{sweep_id}" if isinstance(sweep_id, str) and sweep_id.strip() else f"sweep[{number}]"
    table = parse(SweepTable, body, prefix)
    values = _expand(table.values)
    rig = _merged(rig_raw, geometry, table.geometry)
    lens = _lens(f"{prefix}.lens", table.lens, rig)
    _apply_sweep(rig, table, lens)
    try:
        design = build_bench(rig, rig_dir) if is_bench(rig) else build_design(rate_design_sections(rig), rig_dir)
    except ConfigError as exc:
        raise ConfigError(f"{prefix}.rig.{exc.key}", exc.value, exc.reason) from None
    sensor = design.sensor
    exposure_us = table.exposure_us
    if exposure_us is None:
        stepped = table.kind in ("exposure", "dark") or table.step == "exposure_us"
        exposure_us = float(np.median(values)) if stepped else 1000.0
    within(
        f"{prefix}.exposure_us",
        exposure_us,
        sensor.exposure_min_us,
        sensor.exposure_max_us,
        f"{sensor.name}'s exposure range [µs]",
    )
    within(
        f"{prefix}.gain_db", table.gain_db, sensor.gain_min_db, sensor.gain_max_db, f"{sensor.name}'s gain range [dB]"
    )
    spec = SweepSpec(
        table=table,
        values=values,
        dark_frames=table.frames_per_point if table.dark_frames is None else table.dark_frames,
        exposure_us=float(exposure_us),
        lens=lens,
        sensor_profile=str(rig["sensor"]["profile"]),
        camera=parse(CameraSpec, {**camera, **table.camera}, f"{prefix}.camera"),
        rig_raw=rig,
        design=design,
        **_geometry_settings(prefix, table, design, lens),
    )
    _check_values(spec, sensor)
    _check_dark_mode(table)
    return spec


def _merged(rig_raw: dict, geometry: dict, sweep_geometry: dict) -> dict:
    """The rig file overridden by the plan's geometry, then by the sweep's."""
    rig = copy.deepcopy(rig_raw)
    for table in (geometry, sweep_geometry):
        for section, body in table.items():
            rig.setdefault(section, {}).update(body)
    return rig


def _apply_sweep(rig: dict, table: SweepTable, lens: LensSetting) -> None:
    """The sweep's sensor and lens, written into its rig config (its exposure is the points' own setting)."""
    if table.sensor is not None:
        rig.setdefault("sensor", {})["profile"] = table.sensor
    for key, value in lens.overrides().items():
        apply_override(rig, key, value)


def _lens(key: str, spec: LensTable | Literal["none"] | None, rig: dict) -> LensSetting:
    """The sweep's lens: none, its table, or (not given) the rig's lens."""
    if isinstance(spec, LensTable):
        return spec.setting()
    if spec is None:
        section = rig.get("lens", {})
        return parse(LensTable, {k: section[k] for k in ("focal_length_mm", "f_number") if k in section}, key).setting()
    return NO_LENS


def _check_values(spec: SweepSpec, sensor: SensorProfile) -> None:
    kind, key = spec.table.kind, f"sweep.{spec.table.id}.values"
    if kind in ("exposure", "dark"):
        within(key, spec.values, sensor.exposure_min_us, sensor.exposure_max_us, f"{sensor.name}'s exposure range [µs]")
    elif kind == "gain":
        within(key, spec.values, sensor.gain_min_db, sensor.gain_max_db, f"{sensor.name}'s gain range [dB]")
    elif kind == "light-level":
        within(key, spec.values, 0.0, 1.0, "the light level range")
    elif kind == "geometry":
        _check_geometry_values(spec, sensor)
    elif spec.lens.bare:
        raise ConfigError(f"sweep.{spec.table.id}.lens", "none", "an aperture sweep needs a lens")
    else:
        lo, hi = spec.lens.f_number_range or (limits_of(FNumber).lo, limits_of(FNumber).hi)
        within(key, spec.values, lo, hi, "the lens's f-number range")


def _geometry_settings(prefix: str, table: SweepTable, design: Design | Bench, lens: LensSetting) -> dict:
    """A geometry sweep's fixed target distance (the table's, else the rig's ``operation.altitude_m``) and lens focus
    setting (the table's, else where the model puts the target's image through the port,
    `uwlab.model.focus.target_image_distance_m`); {} for other sweeps. A geometry sweep needs a lens and a design
    rig (not the EMVA bench)."""
    if table.kind != "geometry":
        return {}
    if isinstance(design, Bench):
        raise ConfigError(f"{prefix}.kind", "geometry", "the EMVA 1288 bench has no target to image: use a tank rig")
    if lens.bare:
        raise ConfigError(f"{prefix}.lens", "none", "a geometry sweep needs a lens")
    from uwlab.model.chain import port_geometry
    from uwlab.model.focus import target_image_distance_m

    distance = table.target_distance_m
    if distance is None:
        distance = float(design["operation.altitude_m"])
    focus = table.lens_focus_m
    if focus is None:
        port, n_w, flat, dome, decenter_z = port_geometry(design)
        focus = float(target_image_distance_m(distance, port, n_w, flat, dome, decenter_z))
    return {"lens_focus_m": float(focus), "target_distance_m": float(distance)}


def _check_geometry_values(spec: SweepSpec, sensor: SensorProfile) -> None:
    """A geometry sweep's values within what its step allows: a focus setting beyond the focal length (a lens
    focuses no closer), a target beyond the port (the flat port's air gap and thickness), an f-number within the
    lens's range, an exposure within the sensor's with a moving target (``operation.speed_m_s`` > 0)."""
    table, key = spec.table, f"sweep.{spec.table.id}.values"
    design = spec.design
    step = table.step
    focal_m = spec.lens.focal_length_mm * 1e-3 if spec.lens.focal_length_mm is not None else 0.0
    hi = limits_of(DistanceM).hi
    if step == "lens_focus_m":
        within(key, spec.values, focal_m * 1.001, hi, "focus settings beyond the focal length [m]")
    elif step == "target_distance_m":
        within(key, spec.values, _port_depth_m(design) * 1.001, hi, "distances beyond the port [m]")
    elif step == "f_number":
        lo, top = spec.lens.f_number_range or (limits_of(FNumber).lo, limits_of(FNumber).hi)
        within(key, spec.values, lo, top, "the lens's f-number range")
    else:
        within(key, spec.values, sensor.exposure_min_us, sensor.exposure_max_us, f"{sensor.name}'s exposure range [µs]")
        if isinstance(design, Bench) or not float(design["operation.speed_m_s"]) > 0:
            raise ConfigError(
                f"sweep.{table.id}.step",
                step,
                "an exposure step measures motion blur: the rig needs a moving target (operation.speed_m_s > 0)",
            )
    fixed = {"lens_focus_m": spec.lens_focus_m, "target_distance_m": spec.target_distance_m}
    if step != "lens_focus_m" and fixed["lens_focus_m"] is not None and not fixed["lens_focus_m"] > focal_m:
        raise ConfigError(f"sweep.{table.id}.lens_focus_m", fixed["lens_focus_m"], "must be beyond the focal length")
    depth = _port_depth_m(design)
    if (
        step != "target_distance_m"
        and fixed["target_distance_m"] is not None
        and not fixed["target_distance_m"] > depth
    ):
        raise ConfigError(
            f"sweep.{table.id}.target_distance_m", fixed["target_distance_m"], f"must be beyond the port ({depth:g} m)"
        )


def _port_depth_m(design: Design | Bench) -> float:
    """How far from the pupil the water begins: a flat port's air gap plus its thickness (0 for a dome)."""
    if isinstance(design, Bench) or design["housing.port"] != "flat":
        return 0.0
    return (float(design["housing.flat_air_gap_mm"]) + float(design["housing.flat_thickness_mm"])) * 1e-3


def _check_dark_mode(table: SweepTable) -> None:
    if table.dark == "block" and table.step == "exposure_us":
        raise ConfigError(
            f"sweep.{table.id}.dark",
            "block",
            "a geometry sweep stepping exposure_us changes the camera settings at every point: use 'point'",
        )
    if table.dark == "block" and table.kind in ("exposure", "gain"):
        raise ConfigError(
            f"sweep.{table.id}.dark",
            "block",
            f"an {table.kind} sweep changes the camera settings at every point: use 'point'",
        )


def resolved_rig(design: Design | Bench) -> dict:
    """The validated design of a sweep as plain TOML-able sections (defaults filled, paths absolute)."""

    def table(body: dict) -> dict:
        return {k: to_jsonable(v) for k, v in body.items() if v is not None}

    return {
        section: [table(b) for b in body] if isinstance(body, list) else table(body)
        for section, body in design.values.items()
    }
