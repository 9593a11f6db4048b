"""The explorer's form: one section per table of the design config, one field per key, read from the config's
schema (`uwlab.model.config.DesignConfig`, through pydantic's JSON Schema) so that a key added to the schema
appears on the page with its description, unit and limits, and no list of keys is kept here.

Each field says what the page needs to show and edit it: the dotted key, the description, the unit, whether it is
required, its default, the words it accepts (``max-blur``, ``fresnel``, a `Literal`'s values), whether free text
(a name or a file) is accepted, numeric limits (for the slider), and whether `--grid` can vary it (a `Grid`
quantity, for the sweep panel).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from functools import cache

from uwlab.model.config import DesignConfig
from uwlab.model.schema import Schema


@dataclass(frozen=True)
class Limits:
    """A numeric field's range: [lo, hi], ends excluded when open; integer values only when `integer`."""

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False


@dataclass(frozen=True)
class FormField:
    key: str
    name: str
    description: str
    unit: str = ""
    required: bool = False
    default: object = None
    words: tuple[str, ...] = ()
    text: bool = False
    number: Limits | None = None
    grid: bool = False
    list_length: int | None = None

    @property
    def choice(self) -> bool:
        """Only words are accepted (a `Literal`): a select."""
        return bool(self.words) and not self.text and self.number is None and self.list_length is None


@dataclass(frozen=True)
class FormSection:
    name: str
    title: str
    fields: tuple[FormField, ...] = field(default_factory=tuple)


def _resolve(schema: dict, defs: dict) -> dict:
    ref = schema.get("$ref")
    return defs[ref.rsplit("/", 1)[-1]] if ref else schema


def _limits(schema: dict) -> Limits | None:
    if schema.get("type") not in ("number", "integer"):
        return None
    lo = schema.get("minimum", schema.get("exclusiveMinimum"))
    hi = schema.get("maximum", schema.get("exclusiveMaximum"))
    if lo is None or hi is None:
        return None
    return Limits(lo, hi, "exclusiveMinimum" in schema, "exclusiveMaximum" in schema, schema["type"] == "integer")


def _field(section: str, name: str, schema: dict, required: bool) -> FormField:
    members = schema.get("anyOf") or schema.get("oneOf") or [schema]
    members = [m for m in members if m.get("type") != "null"]
    words, text, number, unit, grid, length = [], False, None, "", False, None
    for member in members:
        kind = member.get("type")
        if "enum" in member or "const" in member:
            words += [str(w) for w in member.get("enum", [member.get("const")])]
        elif kind == "string":
            text = True
        elif kind in ("number", "integer"):
            number = _limits(member)
            unit = member.get("unit", unit)
            grid = grid or bool(member.get("grid"))
        elif kind == "array":
            length = member.get("maxItems")
            unit = member.get("items", {}).get("unit", unit)
        else:
            text = True  # anything else is typed as a value, in TOML syntax
    return FormField(
        key=f"{section}.{name}",
        name=name,
        description=schema.get("description", ""),
        unit=unit,
        required=required,
        default=schema.get("default"),
        words=tuple(words),
        text=text,
        number=number,
        grid=grid,
        list_length=length,
    )


@cache
def form(config: type[Schema] = DesignConfig) -> tuple[FormSection, ...]:
    """The form of the design config (or another config schema of sections), sections and keys in its order. Arrays
    of tables (the extended model's [[lights]]) are not form sections: they are edited in the TOML."""
    schema = config.model_json_schema()
    defs = schema.get("$defs", {})
    sections = []
    for name, prop in schema["properties"].items():
        body = _resolve(prop, defs)
        if body.get("type") == "array":
            continue
        required = set(body.get("required", ()))
        title = body.get("description", "").split("\n")[0]
        fields = tuple(
            _field(name, key, _resolve(sub, defs), key in required) for key, sub in body.get("properties", {}).items()
        )
        sections.append(FormSection(name, title, fields))
    return tuple(sections)


def form_json() -> list[dict]:
    return [
        asdict(section) | {"fields": [asdict(f) | {"choice": f.choice} for f in section.fields]} for section in form()
    ]


def gridable_keys() -> list[str]:
    """The keys `uwlab design --grid` can vary over numbers (the sweep panel's choices)."""
    return [f.key for section in form() for f in section.fields if f.grid]
