"""Sweep plans: a TOML file naming the rig, its geometry and one or more ``[[sweep]]`` tables.

Schema (docs/sweeps.md has a commented example). Top level:

- ``name``, ``description`` (text); ``rig`` (required): a design config (`uwlab design` sections, plus the
  simulated rig's ``[sim]``), relative to the plan file; ``[geometry]``: design sections overriding the rig for
  every sweep (``[geometry.light] distance_m = 1.2``);
- ``[camera]``: ``backend``, ``id``, ``pixel_format``, ``window`` = [x, y, w, h] (device ROI), ``timeout_s``;
- ``[instruments]``: ``light_port``, ``spectrometer_port``, ``protocol`` (real hardware; ``--sim`` replaces them);
- ``[defaults]``: any sweep key, applied to every sweep unless the sweep sets it.

Each ``[[sweep]]``: ``id`` (unique), ``kind`` (exposure | aperture | gain | light-level | dark), ``values``
(a list, or ``{start, stop, num, spacing = "linear" | "log"}``: exposure_us, f-number, gain_db or light level;
a dark sweep steps exposure_us with the light off), ``frames_per_point`` (≥ 2), ``settle_s``, ``dark``
("point": dark frames at every point, "block": once per sweep, only when camera settings stay fixed, "none"),
``dark_frames`` (≥ 2), ``spectrometer`` (positions read at each point: "target", "camera"; the first gives the
point's ``irradiance_w_m2``), ``spectrometer_integration_ms``, ``spectrometer_averaging``, ``roi`` ([x, y, w, h]
within the acquired image, or "aruco"), ``aruco_dictionary``, ``saturation_threshold`` (fraction of ROI pixels
at the camera's clip level above which a point is flagged; `uwlab.experiments.saturation`),
``lens`` ("none", or ``{focal_length_mm, f_number, f_number_range = [lo, hi], manual = true}``), ``sensor`` (the
sensor profile: sets the rig's ``sensor.profile``; the simulated camera uses it), ``camera`` (a table overriding
``[camera]``), the fixed settings ``exposure_us``, ``gain_db``, ``black_level_dn``, ``light_level``,
``save_frames`` (TIFFs under ``frames/``) and ``geometry`` (design overrides for this sweep only).

No lens: the resolved rig of a "no lens" sweep carries the bare sensor's f-number and transmittance
(`uwlab.model.optics.NO_LENS`); its rows have null focal length and f-number.

Unknown keys and impossible values raise `ConfigError` naming the key (``sweep.<id>.<key>``).
"""
from __future__ import annotations

import copy
import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from uwlab.drivers.camera.pixels import PIXEL_FORMATS
from uwlab.errors import ConfigError
from uwlab.experiments.saturation import POINT_SATURATED_FRACTION
from uwlab.jsonable import to_jsonable
from uwlab.model.config import apply_override
from uwlab.model.data import read_toml, resolve_path
from uwlab.model.design import SPECTROMETER_POSITIONS, Design, build_design
from uwlab.model.optics import NO_LENS, LensSetting

KINDS = ("exposure", "aperture", "gain", "light-level", "dark")
DARK_MODES = ("point", "block", "none")
TOP_KEYS = ("name", "description", "rig", "geometry", "camera", "instruments", "defaults", "sweep")
CAMERA_KEYS = ("backend", "id", "pixel_format", "window", "timeout_s")
INSTRUMENT_KEYS = ("light_port", "spectrometer_port", "protocol")
LENS_KEYS = ("focal_length_mm", "f_number", "f_number_range", "manual")
RANGE_KEYS = ("start", "stop", "num", "spacing")
SWEEP_DEFAULTS: dict[str, Any] = {
    "frames_per_point": 2, "settle_s": 0.0, "dark": "point", "dark_frames": None, "spectrometer": [],
    "spectrometer_integration_ms": 10.0, "spectrometer_averaging": 1, "roi": None, "aruco_dictionary": "DICT_4X4_50",
    "saturation_threshold": POINT_SATURATED_FRACTION, "lens": None, "sensor": None, "camera": {},
    "exposure_us": None, "gain_db": 0.0, "black_level_dn": None, "light_level": 1.0, "save_frames": False,
    "geometry": {},
}
SWEEP_KEYS = ("id", "kind", "values", *SWEEP_DEFAULTS)
MAX_POINTS = 10000


@dataclass(frozen=True)
class CameraSpec:
    backend: str = "sim"
    device_id: str | None = None
    pixel_format: str | None = None
    window: tuple[int, int, int, int] | None = None
    timeout_s: float = 5.0


@dataclass(frozen=True)
class Point:
    """The settings of one point of a sweep (None: the sweep's fixed setting applies)."""

    index: int
    exposure_us: float
    gain_db: float
    f_number: float | None
    light_level: float
    light_on: bool


@dataclass(frozen=True)
class SweepSpec:
    id: str
    kind: str
    values: tuple[float, ...]
    frames_per_point: int
    settle_s: float
    dark: str
    dark_frames: int
    spectrometer: tuple[str, ...]
    spectrometer_integration_ms: float
    spectrometer_averaging: int
    roi: tuple[int, int, int, int] | str | None
    aruco_dictionary: str
    saturation_threshold: float
    lens: LensSetting
    sensor_profile: str
    camera: CameraSpec
    exposure_us: float
    gain_db: float
    black_level_dn: float | None
    light_level: float
    save_frames: bool
    rig_raw: dict
    design: Design

    def points(self) -> list[Point]:
        """Every point of the sweep, in order."""
        return [self._point(i, v) for i, v in enumerate(self.values)]

    def _point(self, index: int, value: float) -> Point:
        settings = {"exposure_us": self.exposure_us, "gain_db": self.gain_db, "f_number": self.lens.f_number,
                    "light_level": self.light_level}
        key = {"exposure": "exposure_us", "dark": "exposure_us", "gain": "gain_db", "aperture": "f_number",
               "light-level": "light_level"}[self.kind]
        settings[key] = value
        return Point(index=index, light_on=self.kind != "dark", **settings)


@dataclass(frozen=True)
class Plan:
    path: Path
    sha256: str
    raw: dict
    name: str
    rig_path: Path
    sweeps: tuple[SweepSpec, ...]
    instruments: dict

    def total_points(self) -> int:
        return sum(len(s.values) for s in self.sweeps)


def plan_sha256(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def load_plan(path: str | Path) -> Plan:
    """Read, validate and resolve a plan file (`ConfigError` naming the key on any problem)."""
    path = Path(path)
    raw = read_toml(path, "plan")
    return parse_plan(raw, path, plan_sha256(path))


def parse_plan(raw: dict, path: Path, sha256: str) -> Plan:
    _unknown("", raw, TOP_KEYS)
    if "rig" not in raw or not isinstance(raw["rig"], str):
        raise ConfigError("rig", raw.get("rig"), "required: path of the rig's design config (e.g. ../rigs/sim-tank.toml)")
    base = path.resolve().parent
    rig_path = resolve_path(raw["rig"], base)
    rig_raw = read_toml(rig_path, "rig")
    geometry = _table("geometry", raw.get("geometry", {}))
    camera = _table("camera", raw.get("camera", {}))
    _unknown("camera", camera, CAMERA_KEYS)
    instruments = _table("instruments", raw.get("instruments", {}))
    _unknown("instruments", instruments, INSTRUMENT_KEYS)
    defaults = _table("defaults", raw.get("defaults", {}))
    _unknown("defaults", defaults, tuple(k for k in SWEEP_KEYS if k != "id"))
    tables = raw.get("sweep")
    if not isinstance(tables, list) or not tables:
        raise ConfigError("sweep", tables, "at least one [[sweep]] table is required")
    sweeps = []
    for number, table in enumerate(tables):
        body = _table(f"sweep[{number}]", table)
        sweeps.append(_sweep({**defaults, **body}, number, rig_raw, rig_path.parent, geometry, camera))
    ids = [s.id for s in sweeps]
    duplicated = sorted({i for i in ids if ids.count(i) > 1})
    if duplicated:
        raise ConfigError("sweep.id", duplicated[0], "sweep ids must be unique within the plan")
    return Plan(path=path, sha256=sha256, raw=raw, name=str(raw.get("name", path.stem)), rig_path=rig_path,
                sweeps=tuple(sweeps), instruments=instruments)


def point_counts(raw: dict) -> dict[str, int]:
    """``{sweep_id: number of points}`` of a parsed plan TOML (as stored in a dataset's metadata)."""
    defaults = raw.get("defaults", {}) if isinstance(raw.get("defaults"), dict) else {}
    counts = {}
    for number, table in enumerate(raw.get("sweep", [])):
        body = {**defaults, **table}
        counts[str(body.get("id", number))] = len(expand_values(f"sweep.{body.get('id', number)}.values", body.get("values")))
    return counts


def expand_values(key: str, spec: Any) -> tuple[float, ...]:
    """A sweep's values: a non-empty list of numbers, or ``{start, stop, num, spacing}`` (both ends included)."""
    if isinstance(spec, list):
        if not spec or len(spec) > MAX_POINTS or not all(_is_number(v) for v in spec):
            raise ConfigError(key, spec, f"must be a list of 1 to {MAX_POINTS} numbers or a range table")
        return tuple(float(v) for v in spec)
    if not isinstance(spec, dict):
        raise ConfigError(key, spec, "must be a list of numbers or {start, stop, num, spacing}")
    _unknown(key, spec, RANGE_KEYS)
    for name in ("start", "stop", "num"):
        if not _is_number(spec.get(name)):
            raise ConfigError(f"{key}.{name}", spec.get(name), "required number")
    num, spacing = spec["num"], spec.get("spacing", "linear")
    if not isinstance(num, int) or not 1 <= num <= MAX_POINTS:
        raise ConfigError(f"{key}.num", num, f"must be an integer in [1, {MAX_POINTS}]")
    if spacing == "linear":
        return tuple(float(v) for v in np.linspace(spec["start"], spec["stop"], num))
    if spacing == "log":
        if spec["start"] <= 0 or spec["stop"] <= 0:
            raise ConfigError(f"{key}.start", spec["start"], "log spacing needs positive start and stop")
        return tuple(float(v) for v in np.geomspace(spec["start"], spec["stop"], num))
    raise ConfigError(f"{key}.spacing", spacing, "must be 'linear' or 'log'")


def _sweep(body: dict, number: int, rig_raw: dict, rig_dir: Path, geometry: dict, camera: dict) -> SweepSpec:
    sweep_id = body.get("id")
    if not isinstance(sweep_id, str) or not sweep_id.strip():
        raise ConfigError(f"sweep[{number}].id", sweep_id, "required non-empty string")
    prefix = f"sweep.{sweep_id}"
    _unknown(prefix, body, SWEEP_KEYS)
    opts = {**SWEEP_DEFAULTS, **body}
    kind = opts.get("kind")
    if kind not in KINDS:
        raise ConfigError(f"{prefix}.kind", kind, f"must be one of {', '.join(KINDS)}")
    values = expand_values(f"{prefix}.values", body.get("values"))
    rig = _merged(prefix, rig_raw, geometry, opts)
    lens = _lens(f"{prefix}.lens", opts["lens"], rig)
    _apply_sweep(prefix, rig, opts, lens)
    try:
        design = build_design({k: v for k, v in rig.items() if k != "sim"}, rig_dir)
    except ConfigError as exc:
        raise ConfigError(f"{prefix}.rig.{exc.key}", exc.value, exc.reason) from None
    sensor = design.sensor
    frames = _integer(f"{prefix}.frames_per_point", opts["frames_per_point"], 2)
    dark_frames = _integer(f"{prefix}.dark_frames", frames if opts["dark_frames"] is None else opts["dark_frames"], 2)
    exposure_us = opts["exposure_us"]
    if exposure_us is None:
        exposure_us = float(np.median(values)) if kind in ("exposure", "dark") else 1000.0
    spec = SweepSpec(
        id=sweep_id, kind=kind, values=values, frames_per_point=frames,
        settle_s=_number(f"{prefix}.settle_s", opts["settle_s"], 0.0, 3600.0),
        dark=_choice(f"{prefix}.dark", opts["dark"], DARK_MODES), dark_frames=dark_frames,
        spectrometer=_positions(f"{prefix}.spectrometer", opts["spectrometer"]),
        spectrometer_integration_ms=_number(f"{prefix}.spectrometer_integration_ms",
                                            opts["spectrometer_integration_ms"], 1.0, 10000.0),
        spectrometer_averaging=_integer(f"{prefix}.spectrometer_averaging", opts["spectrometer_averaging"], 1, 100),
        roi=_roi(f"{prefix}.roi", opts["roi"]), aruco_dictionary=_aruco_name(f"{prefix}.aruco_dictionary",
                                                                            opts["aruco_dictionary"]),
        saturation_threshold=_number(f"{prefix}.saturation_threshold", opts["saturation_threshold"], 0.0, 1.0),
        lens=lens, sensor_profile=str(rig["sensor"]["profile"]),
        camera=_camera(f"{prefix}.camera", {**camera, **_table(f"{prefix}.camera", opts["camera"])}),
        exposure_us=_number(f"{prefix}.exposure_us", exposure_us, sensor.exposure_min_us, sensor.exposure_max_us),
        gain_db=_number(f"{prefix}.gain_db", opts["gain_db"], sensor.gain_min_db, sensor.gain_max_db),
        black_level_dn=None if opts["black_level_dn"] is None else _number(f"{prefix}.black_level_dn",
                                                                            opts["black_level_dn"], 0.0, 2.0**32),
        light_level=_number(f"{prefix}.light_level", opts["light_level"], 0.0, 1.0),
        save_frames=_bool(f"{prefix}.save_frames", opts["save_frames"]),
        rig_raw=rig, design=design,
    )
    _check_values(spec, sensor)
    _check_dark_mode(spec)
    return spec


def _merged(prefix: str, rig_raw: dict, geometry: dict, opts: dict) -> dict:
    """The rig file overridden by the plan's geometry, then by the sweep's."""
    rig = copy.deepcopy(rig_raw)
    for source, table in (("geometry", geometry), (f"{prefix}.geometry", _table(f"{prefix}.geometry", opts["geometry"]))):
        for section, body in table.items():
            if section == "sim" or not isinstance(body, dict):
                raise ConfigError(f"{source}.{section}", body, "must be a design section table ([geometry.<section>])")
            rig.setdefault(section, {}).update(body)
    return rig


def _apply_sweep(prefix: str, rig: dict, opts: dict, lens: LensSetting) -> None:
    """The sweep's sensor, lens and fixed exposure, written into its rig config."""
    if opts["sensor"] is not None:
        if not isinstance(opts["sensor"], str):
            raise ConfigError(f"{prefix}.sensor", opts["sensor"], "must be a sensor profile name")
        rig.setdefault("sensor", {})["profile"] = opts["sensor"]
    for key, value in lens.overrides().items():
        apply_override(rig, key, value)
    exposure = opts["exposure_us"]
    if _is_number(exposure) and exposure > 0:
        rig.setdefault("operation", {})["exposure_s"] = exposure * 1e-6


def _lens(key: str, spec: Any, rig: dict) -> LensSetting:
    if spec == "none":
        return NO_LENS
    if spec is None:
        section = rig.get("lens", {})
        spec = {k: section[k] for k in ("focal_length_mm", "f_number") if k in section}
    if not isinstance(spec, dict):
        raise ConfigError(key, spec, 'must be "none" or {focal_length_mm, f_number, f_number_range, manual}')
    _unknown(key, spec, LENS_KEYS)
    focal = _number(f"{key}.focal_length_mm", spec.get("focal_length_mm"), 0.0, 10000.0, lo_open=True)
    f_number = _number(f"{key}.f_number", spec.get("f_number"), 0.0, 1000.0, lo_open=True)
    bounds = spec.get("f_number_range")
    if bounds is not None:
        if not (isinstance(bounds, list) and len(bounds) == 2 and all(_is_number(v) and v > 0 for v in bounds)
                and bounds[0] <= bounds[1]):
            raise ConfigError(f"{key}.f_number_range", bounds, "must be [lowest, highest] positive f-numbers")
        bounds = (float(bounds[0]), float(bounds[1]))
        if not bounds[0] <= f_number <= bounds[1]:
            raise ConfigError(f"{key}.f_number", f_number, f"outside the lens's range [{bounds[0]:g}, {bounds[1]:g}]")
    return LensSetting(focal, f_number, bounds, _bool(f"{key}.manual", spec.get("manual", True)))


def _check_values(spec: SweepSpec, sensor) -> None:
    key = f"sweep.{spec.id}.values"
    arr = np.asarray(spec.values)
    if spec.kind in ("exposure", "dark"):
        _within(key, arr, sensor.exposure_min_us, sensor.exposure_max_us, f"{sensor.name}'s exposure range [µs]")
    elif spec.kind == "gain":
        _within(key, arr, sensor.gain_min_db, sensor.gain_max_db, f"{sensor.name}'s gain range [dB]")
    elif spec.kind == "light-level":
        _within(key, arr, 0.0, 1.0, "the light level range")
    elif spec.lens.bare:
        raise ConfigError(f"sweep.{spec.id}.lens", "none", "an aperture sweep needs a lens")
    else:
        lo, hi = spec.lens.f_number_range or (np.nextafter(0.0, 1.0), np.inf)
        _within(key, arr, lo, hi, "the lens's f-number range")


def _check_dark_mode(spec: SweepSpec) -> None:
    if spec.dark == "block" and spec.kind in ("exposure", "gain"):
        raise ConfigError(f"sweep.{spec.id}.dark", "block",
                          f"an {spec.kind} sweep changes the camera settings at every point: use 'point'")


def _within(key: str, arr: np.ndarray, lo: float, hi: float, what: str) -> None:
    bad = (arr < lo) | (arr > hi)
    if np.any(bad):
        raise ConfigError(key, float(arr[bad][0]), f"outside {what} [{lo:g}, {hi:g}]")


def _camera(key: str, body: dict) -> CameraSpec:
    _unknown(key, body, CAMERA_KEYS)
    fmt = body.get("pixel_format")
    if fmt is not None and fmt not in PIXEL_FORMATS:
        raise ConfigError(f"{key}.pixel_format", fmt, f"must be one of {', '.join(PIXEL_FORMATS)}")
    for name in ("backend", "id"):
        if name in body and not isinstance(body[name], str):
            raise ConfigError(f"{key}.{name}", body[name], "must be a string")
    return CameraSpec(backend=body.get("backend", "sim"), device_id=body.get("id"), pixel_format=fmt,
                      window=_rectangle(f"{key}.window", body["window"]) if "window" in body else None,
                      timeout_s=_number(f"{key}.timeout_s", body.get("timeout_s", 5.0), 0.0, 600.0, lo_open=True))


def _roi(key: str, value: Any) -> tuple[int, int, int, int] | str | None:
    if value is None or value == "aruco":
        return value
    return _rectangle(key, value)


def _rectangle(key: str, value: Any) -> tuple[int, int, int, int]:
    ok = isinstance(value, list) and len(value) == 4 and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
    if not ok or value[0] < 0 or value[1] < 0 or value[2] < 2 or value[3] < 2:
        raise ConfigError(key, value, 'must be [x, y, width, height] in pixels (offsets >= 0, sizes >= 2) or "aruco"'
                          if key.endswith("roi") else "must be [x, y, width, height] in pixels")
    return tuple(value)


def _aruco_name(key: str, value: Any) -> str:
    import cv2

    if not isinstance(value, str) or not value.startswith("DICT_") or not hasattr(cv2.aruco, value):
        raise ConfigError(key, value, "must name a cv2.aruco predefined dictionary, e.g. DICT_4X4_50")
    return value


def _positions(key: str, value: Any) -> tuple[str, ...]:
    if not isinstance(value, list) or any(v not in SPECTROMETER_POSITIONS for v in value) or len(set(value)) != len(value):
        raise ConfigError(key, value, f"must be a list of distinct positions from {', '.join(SPECTROMETER_POSITIONS)}")
    return tuple(value)


def _unknown(prefix: str, body: dict, allowed: tuple[str, ...]) -> None:
    for key in body:
        if key not in allowed:
            name = f"{prefix}.{key}" if prefix else key
            raise ConfigError(name, body[key], f"unknown key; allowed: {', '.join(allowed)}")


def _table(key: str, value: Any) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(key, value, "must be a table")
    return value


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)


def _number(key: str, value: Any, lo: float, hi: float, lo_open: bool = False) -> float:
    if not _is_number(value) or value < lo or value > hi or (lo_open and value == lo):
        left = "(" if lo_open else "["
        raise ConfigError(key, value, f"must be a number in {left}{lo:g}, {hi:g}]")
    return float(value)


def _integer(key: str, value: Any, lo: int, hi: int = 1_000_000) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not lo <= value <= hi:
        raise ConfigError(key, value, f"must be an integer in [{lo}, {hi}]")
    return value


def _choice(key: str, value: Any, options: tuple[str, ...]) -> str:
    if value not in options:
        raise ConfigError(key, value, f"must be one of {', '.join(options)}")
    return value


def _bool(key: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(key, value, "must be true or false")
    return value


def resolved_rig(design: Design) -> dict:
    """The validated design of a sweep as plain TOML-able sections (defaults filled, paths absolute)."""
    return {section: {k: to_jsonable(v) for k, v in body.items() if v is not None}
            for section, body in design.values.items()}

