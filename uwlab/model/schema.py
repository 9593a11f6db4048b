"""The config-schema layer: what every configuration file and numeric option of uwlab is validated with.

Schemas are pydantic v2 models (`Schema`: unknown keys are refused) that live next to what they configure
(`uwlab.model.config`, `uwlab.model.sensor`, `uwlab.sim.scene`, `uwlab.experiments.acquisition.plan`,
`uwlab.experiments.calibration`). This module holds what they share:

- `Limits`: an interval with a unit, checked on numbers (strictly: no strings, no booleans, finite) and, for
  grid-able design keys (``Grid[...]``), element-wise on numpy arrays, vectorised.
- The named physical quantities below, each with plausibility limits chosen so that a value outside them is
  almost certainly a unit mistake (a focal length in metres, a wavelength in µm, a pixel pitch in nm) rather
  than an unusual design. Every input of that quantity (design keys, sensor profiles, plans, CLI options) uses
  the same type, so the same mistake is caught everywhere with the same words.
- `parse` and `check`: validate a mapping against a model, or one value against a type, and turn pydantic's
  `ValidationError` into the one-line `ConfigError` ``key = value: reason`` naming the dotted key
  (``lens.focal_length_mm``, ``sweep.<id>.frames_per_point``, ``parameters.K_dn_per_e:imx250m.sigma``) and
  the offending value (for arrays and lists: the first offending element).

Plausibility limits of the named quantities (a value outside is refused; the reason says what it likely is):

- `WavelengthNm` 200–2500 nm: every silicon, InGaAs and UV sensor and light source uwlab models; 0.55 (µm) or
  5.5e-7 (m) is outside. `SpectralStepNm` 0.01–100 nm (tabulated spectra are 1–10 nm apart).
- `FocalLengthMm` 1–2000 mm: fisheye board lenses to super-telephoto; 0.03 (m) is outside (it gave FOV 179°).
- `FNumber` 0.5–128: 0.5 is the aplanatic limit in air (the bare sensor's N, `uwlab.model.optics`), 128 the
  smallest apertures of large-format lenses; an aperture diameter or an f-stop index falls outside.
- `PixelSizeUm` 0.5–50 µm: smallest phone pixels to large scientific pixels; 3450 (nm) gave η > 1.
- `DistanceM` 1 mm–12 km (altitude, light distance, depth of field): closer than any lens focuses to the deepest
  ocean; 1e308 is outside, and so is 1e-308 (a unit error that gave a minimum f-number of −4087).
- `LuminousFluxLm` 1 mlm–1e7 lm: an indicator LED to ~100 subsea lights (the brightest give ~1e5 lm);
  `IrradianceWM2` 1e-9–1e5 W/m²: a dim dark-room level to 100 suns.
- `ExposureS` 1 µs–1 h (`ExposureUs` the same in µs): the shortest global-shutter exposure to long dark frames.
- `GainDb` −20–80 dB: cameras span 0–48 dB; a linear factor (1000) or centi-dB is outside.
- `HalfAngleDeg` [0.1, 90), `IncidenceDeg` [0, 90) deg: a collimated beam to the hemisphere (radians cannot be
  told apart).
- `RefractiveIndex` 1–4: vacuum to germanium. `Fraction` [0, 1], `Transmittance` 1e-6–1 (an ND 6 filter to
  clear): a percentage (90) is outside, and so is a transmittance that leaves nothing to measure.
- `SpeedMS` 0–50 m/s: the fastest underwater vehicles; km/h or mm/s beyond.
- `HousingMm` 0.5–1000 mm (port and dome sizes): a size in m (0.1) is below, in µm above.
- `CircleOfConfusionMm` 1e-4–1 mm: typically 0.002–0.03 mm (a pixel or two); a value in µm is above.
- `BlurPx` 0.01–1000 px; `BitDepth` 1–32 bit; `DurationS` 0–1 h (settling times).
- `PositionM` −100–100 m: a light's or instrument's position relative to the camera on a vehicle or in a tank; a
  position in mm is outside. `ScatteringPerM` 0–100 1/m: clear ocean ~0.002 (pure water), harbours ~2, the
  muddiest estuaries tens; a value in 1/km or 1/cm is outside.
- `FrameCount` 2–10,000 frames per point (and dark frames): EMVA 1288 needs 2 for the photon transfer and ≥ 16
  for nonuniformities (Release 4.0 Linear, §8); more than 10,000 is hours per point at usual frame rates — a
  typo, refused before a sweep starts or anything is allocated.

>>> check(FocalLengthMm, 30, "lens.focal_length_mm")
30.0
>>> check(FocalLengthMm, 0.03, "lens.focal_length_mm")
Traceback (most recent call last):
...
uwlab.errors.ConfigError: lens.focal_length_mm = 0.03: must be in [1, 2000] mm — is the unit right?
"""

from __future__ import annotations

import types
import typing
from dataclasses import dataclass, replace
from functools import cache
from collections.abc import Callable, Mapping
from typing import Annotated, Any, Literal, TypeVar, Union

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    GetCoreSchemaHandler,
    StringConstraints,
    Tag,
    TypeAdapter,
    ValidationError,
    WrapValidator,
)
from pydantic_core import PydanticCustomError, core_schema

from uwlab.errors import ConfigError

M = TypeVar("M", bound=BaseModel)
UNIT_HINT = "is the unit right?"


class Schema(BaseModel):
    """Base of every config schema: unknown keys are errors, validated objects are immutable; numpy arrays may
    appear as (grid) values."""

    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)


@dataclass(frozen=True)
class Limits:
    """A number in [lo, hi] (``lo_open``/``hi_open``: excluded) with its unit; ``integer`` demands integral
    values (given as int or float) and returns an int; ``hint`` follows the range in the error (the likely
    mistake). As pydantic metadata: ``Annotated[float, Limits(...)]``.

    Numbers are strict: a string, a boolean, inf or nan is refused. With ``grid`` a numpy array is accepted
    too and checked element-wise (`Grid`).
    """

    lo: float
    hi: float
    unit: str = ""
    hint: str = ""
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False
    grid: bool = False

    def describe(self) -> str:
        """The error reason, e.g. ``must be in [1, 2000] mm — is the unit right?``."""
        kind = "an integer in" if self.integer else "in"
        interval = f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"
        unit = f" {self.unit}" if self.unit else ""
        return f"must be {kind} {interval}{unit}" + (f" — {self.hint}" if self.hint else "")

    def _bad(self, x: np.ndarray) -> np.ndarray:
        bad = ~np.isfinite(x) | (x < self.lo) | (x > self.hi)
        if self.lo_open:
            bad |= x == self.lo
        if self.hi_open:
            bad |= x == self.hi
        if self.integer:
            bad |= x != np.round(x)
        return bad

    def check(self, value):
        """The value as float (int when ``integer``) or float array, or `PydanticCustomError` with the reason."""
        if isinstance(value, np.ndarray):
            if value.dtype.kind not in "iuf":
                raise PydanticCustomError("number_type", "must be numbers")
            arr = value.astype(float)
            bad = self._bad(arr)
            if bad.any():
                raise PydanticCustomError("limits", self.describe(), {"value": arr[bad].flat[0].item()})
            return arr
        if self._bad(np.float64(value)):
            raise PydanticCustomError("limits", self.describe())
        return int(value) if self.integer else float(value)

    def __get_pydantic_core_schema__(self, source, handler) -> core_schema.CoreSchema:
        return core_schema.no_info_wrap_validator_function(
            self._validate, core_schema.float_schema(strict=True, allow_inf_nan=False)
        )

    def _validate(self, value, number):
        if isinstance(value, np.ndarray) and self.grid:
            return self.check(value)
        if isinstance(value, (np.integer, np.floating)):
            value = value.item()
        return self.check(number(value))

    def __get_pydantic_json_schema__(self, schema, handler) -> dict:
        out = {
            "type": "integer" if self.integer else "number",
            "exclusiveMinimum" if self.lo_open else "minimum": self.lo,
            "exclusiveMaximum" if self.hi_open else "maximum": self.hi,
        }
        if self.unit:
            out["unit"] = self.unit
        if self.grid:
            out["grid"] = True  # `uwlab design --grid` can vary it
        return out


def limits_of(named) -> Limits:
    """The `Limits` of a named quantity type (``Annotated[float, Limits(...)]``)."""
    found = [m for m in getattr(named, "__metadata__", ()) if isinstance(m, Limits)]
    if len(found) != 1:
        raise TypeError(f"{named!r} is not a quantity with one Limits")
    return found[0]


Q = TypeVar("Q")

if typing.TYPE_CHECKING:
    # What the type checker sees: a number or an array.
    Grid = Union[Q, np.ndarray]  # noqa: UP007 (a generic alias)
else:

    class Grid:
        """``Grid[Quantity]``: the quantity as a number or, for grid evaluation (`uwlab design --grid`), a numpy
        array of any shape (an open mesh) checked element-wise in one vectorised pass."""

        def __class_getitem__(cls, named: Any) -> Any:
            found = limits_of(named)
            return Annotated[float | np.ndarray, replace(found, grid=True)]


def limits(lo: float, hi: float, unit: str = "", hint: str = UNIT_HINT, **options: bool) -> Limits:
    """The limits of a named quantity type, ``Annotated[float, limits(lo, hi, unit, ...)]`` (``Annotated[int, ...]``
    with ``integer=True``): its plausible interval, unit and the hint an error gives (by default the unit's)."""
    return Limits(lo, hi, unit, hint, **options)


NonEmptyText = Annotated[str, StringConstraints(strict=True, min_length=1)]
Text = Annotated[str, StringConstraints(strict=True)]
# Any finite number (strict: no strings, no booleans); for quantities with limits use `limits`.
Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]


@dataclass(frozen=True)
class Either:
    """Metadata of a union, ``Annotated[A | B, Either(reason, (test_a, test_b))]``: a value is validated by the first
    member whose test accepts it (``test_a`` for ``A``, …), e.g. ``Annotated[Literal["none"] | LensTable,
    either("…", is_text, is_table)]``; a value no test accepts fails with `reason`. The type checker sees the union."""

    reason: str
    tests: tuple[Callable[[Any], bool], ...]

    def __get_pydantic_core_schema__(self, source: Any, handler: GetCoreSchemaHandler) -> core_schema.CoreSchema:
        members = typing.get_args(source)
        if len(members) != len(self.tests):
            raise TypeError(f"{source!r}: {len(self.tests)} tests for {len(members)} union members")
        return handler.generate_schema(self._tagged(members))

    def _tagged(self, members: tuple[Any, ...]) -> Any:
        """The union of `members`, each tagged with its index, chosen by the first test that accepts the value."""
        tests, reason = self.tests, self.reason

        def which(value: Any) -> str | None:
            return next((str(i) for i, test in enumerate(tests) if test(value)), None)

        def words(value: Any, handler: Callable[[Any], Any]) -> Any:  # a word not one of a Literal's: the reason
            try:
                return handler(value)
            except ValidationError:
                raise PydanticCustomError("either", reason) from None

        tagged = [
            Annotated[type_, WrapValidator(words), Tag(str(i))]
            if typing.get_origin(type_) is Literal
            else Annotated[type_, Tag(str(i))]
            for i, type_ in enumerate(members)
        ]
        choice = Discriminator(which, custom_error_type="either", custom_error_message=reason)
        return Annotated[Union[tuple(tagged)], choice]  # noqa: UP007 (a union of a computed tuple of types)


def either(reason: str, *tests: Callable[[Any], bool]) -> Either:
    """`Either` metadata: one test per member of the annotated union, in order."""
    return Either(reason, tests)


def is_text(value) -> bool:
    return isinstance(value, str)


def is_number(value) -> bool:
    return isinstance(value, (int, float, np.number, np.ndarray)) and not isinstance(value, (bool, np.bool_))


def is_table(value) -> bool:
    return isinstance(value, dict)


def is_list(value) -> bool:
    return isinstance(value, (list, tuple))


def number_or(reason: str) -> Either:
    """`Either` metadata of ``Annotated[Number | Alternative, number_or(reason)]``: a number (of type ``Number``,
    arrays included when it is a `Grid`) or, for strings, ``Alternative`` (a ``Literal`` of words or `NonEmptyText`
    for a name or path); anything else fails with `reason`."""
    return either(reason, is_number, is_text)


# --- Named physical quantities (limits and their reasons: the module docstring). ---------------------------------

WavelengthNm = Annotated[float, limits(200.0, 2500.0, "nm")]
SpectralStepNm = Annotated[float, limits(0.01, 100.0, "nm")]
FocalLengthMm = Annotated[float, limits(1.0, 2000.0, "mm")]
FNumber = Annotated[float, limits(0.5, 128.0, "")]
PixelSizeUm = Annotated[float, limits(0.5, 50.0, "µm")]
DistanceM = Annotated[float, limits(1e-3, 12000.0, "m")]
IrradianceWM2 = Annotated[float, limits(1e-9, 1e5, "W/m²")]
LuminousFluxLm = Annotated[float, limits(1e-3, 1e7, "lm")]
ExposureS = Annotated[float, limits(1e-6, 3600.0, "s")]
ExposureUs = Annotated[float, limits(1.0, 3.6e9, "µs")]
GainDb = Annotated[float, limits(-20.0, 80.0, "dB")]
HalfAngleDeg = Annotated[float, limits(0.1, 90.0, "deg", hint="", hi_open=True)]
IncidenceDeg = Annotated[float, limits(0.0, 90.0, "deg", hint="", hi_open=True)]
RefractiveIndex = Annotated[float, limits(1.0, 4.0, "")]
Fraction = Annotated[float, limits(0.0, 1.0, "", hint="a fraction, not a percentage")]
Transmittance = Annotated[float, limits(1e-6, 1.0, "", hint="a fraction, not a percentage")]
SpeedMS = Annotated[float, limits(0.0, 50.0, "m/s")]
HousingMm = Annotated[float, limits(0.5, 1000.0, "mm")]
CircleOfConfusionMm = Annotated[float, limits(1e-4, 1.0, "mm")]
BlurPx = Annotated[float, limits(0.01, 1000.0, "px", hint="")]
BitDepth = Annotated[int, limits(1, 32, "bit", hint="", integer=True)]
FrameCount = Annotated[int, limits(2, 10000, "frames", hint="", integer=True)]
DurationS = Annotated[float, limits(0.0, 3600.0, "s")]
PositionM = Annotated[float, limits(-100.0, 100.0, "m")]
ScatteringPerM = Annotated[float, limits(0.0, 100.0, "1/m")]
# A random generator's seed (numpy accepts any 32-bit unsigned integer).
Seed = Annotated[int, limits(0, 2**32 - 1, "", hint="", integer=True)]


# --- From ValidationError to ConfigError. ---------------------------------------------------------------------

_TYPE_REASONS = {
    "missing": "missing (required)",
    "union_tag_not_found": "missing (required)",
    "float_type": "must be a number",
    "float_parsing": "must be a number",
    "int_type": "must be an integer",
    "int_from_float": "must be an integer",
    "finite_number": "must be a finite number",
    "string_type": "must be a string",
    "string_too_short": "must be a non-empty string",
    "bool_type": "must be true or false",
    "dict_type": "must be a table",
    "model_type": "must be a table",
    "model_attributes_type": "must be a table",
    "list_type": "must be a list",
    "tuple_type": "must be a list",
}
_COMPARISONS = {
    "greater_than": (">", "gt"),
    "greater_than_equal": (">=", "ge"),
    "less_than": ("<", "lt"),
    "less_than_equal": ("<=", "le"),
}
_NUMBER_ERRORS = ("float_type", "int_type", "number_type")


def parse(model: type[M], data: Any, prefix: str = "") -> M:
    """``model.model_validate(data)``; a `ValidationError` becomes the `ConfigError` of its first error, the
    key prefixed with `prefix` (``sweep.<id>`` gives ``sweep.<id>.key``, ``file.toml:`` gives ``file.toml: key``)."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise config_error(exc, data, model, prefix) from None


@cache
def _adapter(type_) -> TypeAdapter:
    return TypeAdapter(type_)


def check(type_, value: Any, key: str):
    """One value validated against a type (e.g. a named quantity for a CLI option), or `ConfigError` on `key`."""
    try:
        return _adapter(type_).validate_python(value)
    except ValidationError as exc:
        raise config_error(exc, value, type_, key) from None


def within(key: str, value, lo: float, hi: float, what: str):
    """`value` (number or array) inside [lo, hi] of a configured device (e.g. a sensor profile's exposure range,
    ``what`` = "IMX250M's exposure range [µs]"), or `ConfigError` on `key` naming the first value outside."""
    arr = np.asarray(value, float)
    bad = (arr < lo) | (arr > hi)
    if np.any(bad):
        raise ConfigError(key, float(arr[bad].flat[0]), f"outside {what} [{lo:g}, {hi:g}]")
    return value


def invalid(key: str, value: Any, reason: str) -> PydanticCustomError:
    """An error for a model validator: `key` (a field of the model, or dotted below it) and `value` are what the
    `ConfigError` names. Raise it from ``@model_validator(mode="after")``."""
    return PydanticCustomError("invalid", reason, {"key": key, "value": value})


def at_most_one(model: Any, first: str, second: str) -> Any:
    """`model` unless it sets both of two mutually exclusive fields (then an `invalid` error naming ``first``);
    for ``@model_validator(mode="after")``."""
    if getattr(model, first) is not None and getattr(model, second) is not None:
        raise invalid(first, getattr(model, first), f"give at most one of {first} and {second}")
    return model


def config_error(exc: ValidationError, data: Any, model: Any, prefix: str = "") -> ConfigError:
    """The one-line `ConfigError` of the first error of `exc` (validating `data` against `model`); the key is
    `prefix` followed by the error's location."""
    err = exc.errors()[0]
    ctx = err.get("ctx") or {}
    parts = _key_parts(model, data, err["loc"], err["type"])
    if "key" in ctx:
        parts += str(ctx["key"]).split(".")
    if err["type"] in ("union_tag_not_found", "union_tag_invalid"):
        parts.append(str(ctx.get("discriminator", "kind")).strip("'"))
    rest = ".".join(parts)
    key = f"{prefix}{' ' if prefix.endswith(':') else '.'}{rest}" if prefix and rest else (prefix or rest or "config")
    short = err["type"] == "missing" and err["loc"] and isinstance(err["loc"][-1], int)  # a too short tuple
    if "value" in ctx:
        value = ctx["value"]
    elif err["type"] == "union_tag_invalid":
        value = ctx.get("tag")
    elif short:
        value = _data_at(data, err["loc"][:-1])
    elif err["type"] in ("missing", "union_tag_not_found"):
        value = None
    else:
        value = err["input"]
    reason = "has too few items" if short else _reason(err, model, parts, data)
    return ConfigError(key, _plain(value), reason)


def _data_at(data, loc: tuple):
    """The input at an error location (union tags, which are not in the data, skipped)."""
    for part in loc:
        if isinstance(data, dict) and part in data or isinstance(data, (list, tuple)) and isinstance(part, int):
            data = data[part]
    return data


def _plain(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _reason(err: Mapping[str, Any], model, parts: list[str], data) -> str:
    kind, ctx = err["type"], err.get("ctx") or {}
    if kind in _NUMBER_ERRORS and isinstance(err["input"], np.ndarray):
        return "cannot be varied in a grid"
    if kind == "extra_forbidden":
        names = _field_names(model, data, parts[:-1])
        return "unknown key" + (f"; allowed: {', '.join(names)}" if names else "")
    if kind == "literal_error":
        return f"must be one of {ctx['expected']}"
    if kind == "union_tag_invalid":
        return f"must be one of {ctx['expected_tags']}"
    if kind in _TYPE_REASONS:
        return _TYPE_REASONS[kind]
    if kind in ("too_short", "too_long"):
        bound = ctx.get("min_length") if kind == "too_short" else ctx.get("max_length")
        items = "item" if bound == 1 else "items"
        which = "at least" if kind == "too_short" else "at most"
        return f"must have {which} {bound} {items} (has {ctx.get('actual_length')})"
    if kind in _COMPARISONS:
        symbol, name = _COMPARISONS[kind]
        return f"must be {symbol} {ctx[name]}"
    message = err["msg"].removeprefix("Value error, ")
    return message[:1].lower() + message[1:]


def _unwrap(annotation):
    """(origin type, args) with Annotated and Optional removed."""
    while typing.get_origin(annotation) is Annotated:
        annotation = typing.get_args(annotation)[0]
    origin = typing.get_origin(annotation)
    if origin in (Union, types.UnionType):
        members = [a for a in typing.get_args(annotation) if a is not type(None)]
        if len(members) == 1:
            return _unwrap(members[0])
    return annotation


def _model_for(annotation, node):
    """The model class an annotation validates `node` with (a union of models: the member whose Literal fields
    match the node, e.g. a prior's ``kind``), or None."""
    annotation = _unwrap(annotation)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if typing.get_origin(annotation) in (Union, types.UnionType):
        for member in typing.get_args(annotation):
            found = _model_for(member, node)
            if found is not None and _matches(found, node):
                return found
    return None


def _matches(model: type[BaseModel], node) -> bool:
    if not isinstance(node, dict):
        return False
    for name, field in model.model_fields.items():
        if typing.get_origin(_unwrap(field.annotation)) is Literal and name in node:
            if node[name] not in typing.get_args(_unwrap(field.annotation)):
                return False
    return True


def _child(annotation, node, part):
    """(annotation, node) one level down: a model's field, a dict's value or a sequence's element."""
    model = _model_for(annotation, node)
    sub = node.get(part) if isinstance(node, dict) else None
    if model is not None:
        field = next((f for name, f in model.model_fields.items() if part in (name, f.alias)), None)
        return (field.annotation if field else Any), sub
    origin = _unwrap(annotation)
    args = typing.get_args(origin)
    if typing.get_origin(origin) is dict and len(args) == 2:
        return args[1], sub
    if isinstance(part, int) and isinstance(node, (list, tuple)) and part < len(node):
        return (args[0] if args else Any), node[part]
    return Any, sub


def _key_parts(model, data, loc: tuple, kind: str) -> list[str]:
    """The config key of an error location: field and table names kept; the index of a table in an array of tables
    kept as ``name[i]`` (``lights[1].beam_half_angle_deg``); other list indices (the key names the list, the value
    is the element) and union members' tags dropped."""
    parts: list[str] = []
    annotation, node = model, data
    for i, part in enumerate(loc):
        if isinstance(part, int):
            if parts and isinstance(node, list) and part < len(node) and isinstance(node[part], dict):
                parts[-1] = f"{parts[-1]}[{part}]"
            annotation, node = _child(annotation, node, part)
            continue
        fields = _model_for(annotation, node)
        known = fields is not None and any(part in (name, f.alias) for name, f in fields.model_fields.items())
        present = isinstance(node, dict) and part in node
        if known or present or (i == len(loc) - 1 and kind == "missing"):
            parts.append(str(part))
            annotation, node = _child(annotation, node, part)
    return parts


def _field_names(model, data, parts: list[str]) -> list[str]:
    annotation, node = model, data
    for part in parts:
        annotation, node = _child(annotation, node, part)
    found = _model_for(annotation, node)
    return [field.alias or name for name, field in found.model_fields.items()] if found else []
