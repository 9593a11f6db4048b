"""The design configuration: schema, defaults, validation and overrides.

A design config is TOML with sections [spectral], [light], [water], [target], [housing], [lens], [sensor],
[operation]. Every key carries its unit in its name. Numeric keys may hold a number or, for grid evaluation, a
1-D numpy array of numbers; each element is validated. Validation errors are `ConfigError`s naming
``section.key`` and the offending value.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError
from uwlab.model.data import read_toml

REQUIRED = object()


@dataclass(frozen=True)
class Num:
    """A number in an interval; `integer` demands integral values."""

    default: object = REQUIRED
    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False
    words: tuple[str, ...] = ()  # words accepted instead of a number

    def describe(self) -> str:
        left = "(" if self.lo_open else "["
        right = ")" if self.hi_open else "]"
        kind = "an integer" if self.integer else "a number"
        alts = "".join(f' or "{w}"' for w in self.words)
        return f"must be {kind} in {left}{self.lo:g}, {self.hi:g}{right}{alts}"

    def check(self, key: str, value):
        if isinstance(value, str):
            if value in self.words:
                return value
            raise ConfigError(key, value, self.describe())
        if isinstance(value, bool) or not isinstance(value, (int, float, np.ndarray, list)):
            raise ConfigError(key, value, self.describe())
        arr = np.asarray(value, dtype=float) if not isinstance(value, np.ndarray) else value.astype(float)
        bad = ~np.isfinite(arr) | (arr < self.lo) | (arr > self.hi)
        bad |= (arr == self.lo) & self.lo_open
        bad |= (arr == self.hi) & self.hi_open
        if self.integer:
            bad |= arr != np.round(arr)
        if np.any(bad):
            offending = arr[bad].flat[0] if arr.ndim else value
            raise ConfigError(key, float(offending) if not self.integer else int(offending), self.describe())
        return arr if arr.ndim else float(arr)


@dataclass(frozen=True)
class Choice:
    options: tuple[str, ...]
    default: object = REQUIRED

    def check(self, key: str, value):
        if value not in self.options:
            raise ConfigError(key, value, f"must be one of {', '.join(self.options)}")
        return value


@dataclass(frozen=True)
class Text:
    """A name or a path (numbers are accepted where `number` is a Num to try first)."""

    default: object = REQUIRED
    number: Num | None = None

    def check(self, key: str, value):
        if self.number is not None and not isinstance(value, str):
            return self.number.check(key, value)
        if not isinstance(value, str) or not value:
            raise ConfigError(key, value, "must be a non-empty string" + (" or a number" if self.number else ""))
        return value


FRACTION = Num(lo=0.0, hi=1.0)
POSITIVE = dict(lo=0.0, lo_open=True)

SCHEMA: dict[str, dict[str, Num | Choice | Text]] = {
    "spectral": {
        "start_nm": Num(380.0, **POSITIVE), "stop_nm": Num(780.0, **POSITIVE), "step_nm": Num(1.0, **POSITIVE),
    },
    "light": {
        "spectrum": Text("generic-led"),
        "luminous_flux_lm": Num(REQUIRED, **POSITIVE),
        "beam_half_angle_deg": Num(None, lo=0.0, hi=90.0, lo_open=True, hi_open=True),
        "beam_half_angle_in_air_deg": Num(None, lo=0.0, hi=90.0, lo_open=True, hi_open=True),
        "beam_model": Choice(("cone", "disk"), "cone"),
        "count": Num(1, lo=1, integer=True),
        "distance_m": Num(None, **POSITIVE),
        "incidence_deg": Num(0.0, lo=0.0, hi=90.0, hi_open=True),
    },
    "water": {"type": Text(REQUIRED), "attenuation_scale": Num(1.0, lo=0.0)},
    "target": {"reflectance": Text(REQUIRED, number=FRACTION)},
    "housing": {
        "port": Choice(("flat", "dome"), "flat"),
        "water_index": Num(1.333, lo=1.0),
        "port_index": Num(1.49, lo=1.0),
        "port_transmittance": Num("fresnel", lo=0.0, hi=1.0, lo_open=True, words=("fresnel",)),
        "dome_radius_mm": Num(None, **POSITIVE),
        "dome_thickness_mm": Num(None, **POSITIVE),
    },
    "lens": {
        "focal_length_mm": Num(REQUIRED, **POSITIVE),
        "f_number": Num(REQUIRED, **POSITIVE),
        "transmittance": Text(1.0, number=Num(lo=0.0, hi=1.0, lo_open=True)),
    },
    "sensor": {
        "profile": Text(REQUIRED),
        "gain_db": Num(0.0),
        "bit_depth": Num(None, lo=1, hi=32, integer=True),
        "channel": Choice(("combined", "red", "green", "blue"), "combined"),
    },
    "operation": {
        "altitude_m": Num(REQUIRED, **POSITIVE),
        "speed_m_s": Num(0.0, lo=0.0),
        "overlap": Num(0.0, lo=0.0, hi=1.0, hi_open=True),
        "max_blur_px": Num(1.0, **POSITIVE),
        "exposure_s": Num("max-blur", **POSITIVE, words=("max-blur",)),
        "motion_axis": Choice(("x", "y"), "y"),
        "min_dof_m": Num(None, **POSITIVE),
        "circle_of_confusion_mm": Num(None, **POSITIVE),
    },
}


def validate(raw: dict) -> dict[str, dict]:
    """Check every section and key against SCHEMA, fill defaults; returns {section: {key: value}}."""
    if not isinstance(raw, dict):
        raise ConfigError("config", raw, "must be a table of sections")
    for section, body in raw.items():
        if section not in SCHEMA:
            raise ConfigError(section, "...", f"unknown section; expected one of {', '.join(SCHEMA)}")
        if not isinstance(body, dict):
            raise ConfigError(section, body, "must be a table")
        for key in body:
            if key not in SCHEMA[section]:
                raise ConfigError(f"{section}.{key}", body[key], f"unknown key; {section} has {', '.join(SCHEMA[section])}")
    out: dict[str, dict] = {}
    for section, fields in SCHEMA.items():
        body = raw.get(section, {})
        out[section] = {}
        for key, spec in fields.items():
            name = f"{section}.{key}"
            if key in body:
                out[section][key] = spec.check(name, body[key])
            elif spec.default is REQUIRED:
                raise ConfigError(name, None, "missing (required)")
            else:
                out[section][key] = spec.default
    return out


def parse_value(text: str):
    """A `--set` value: TOML syntax if it parses (numbers, booleans, quoted strings), else a bare string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def apply_override(raw: dict, dotted: str, value) -> None:
    """Set raw[section][key] = value for a ``section.key`` path (unknown keys fail later, in `validate`)."""
    section, dot, key = dotted.partition(".")
    if not dot or not section or not key or "." in key:
        raise ConfigError(dotted, value, "expected section.key")
    body = raw.setdefault(section, {})
    if not isinstance(body, dict):
        raise ConfigError(section, body, "must be a table")
    body[key] = value


def load_raw(path: str | Path) -> dict:
    return read_toml(Path(path), "config")
