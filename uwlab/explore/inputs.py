"""What the explorer's page and API send, made into a design config as `uwlab design` makes one from its arguments.

A request body is a JSON object with up to three members, applied in this order:

- ``config``: a whole design config ({section: {key: value}}, as a TOML file gives it) instead of the served one;
  without it the design starts from the served config.
- ``set``: {"section.key": value} with JSON values, applied as `uwlab design --set` applies its parsed values
  (``{"set": {"lens.f_number": 4}}`` is ``--set lens.f_number=4``); ``null`` removes the key (its default applies).
- ``text``: {"section.key": "text"}: values as typed after ``--set section.key=``, parsed by the same rule
  (`uwlab.model.config.parse_value`: TOML syntax if it parses, else a bare word); "" removes the key.

The page sends ``{"config": {}, "text": {...every field...}}``: the design is what its fields say. `field_texts`
turns a config into those texts (and a shareable URL's query). Relative file names in a config are relative to
the served config's folder (an uploaded TOML has no folder of its own); files named relative to the served config
are made absolute when it is loaded, so a saved design names the same files wherever it is saved.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

import tomli_w

from uwlab.errors import ConfigError
from uwlab.model.config import apply_override, load_raw, parse_value
from uwlab.model.design import Design, build_design

BODY_MEMBERS = ("config", "set", "text")


@dataclass(frozen=True)
class Served:
    """The design `uwlab explore` was started with: its raw config, file and the folder relative names resolve in."""

    raw: dict
    base_dir: Path
    path: Path | None = None


def copy_raw(raw: dict) -> dict:
    return {section: dict(body) if isinstance(body, dict) else body for section, body in raw.items()}


def absolute_paths(raw: dict, base_dir: Path) -> dict:
    """A copy of `raw` where each string naming an existing file relative to `base_dir` is that file's absolute
    path (names such as ``jerlov-I`` or ``imx250m`` are not files and stay as they are)."""
    out = copy_raw(raw)
    for body in out.values():
        if isinstance(body, dict):
            for key, value in body.items():
                if isinstance(value, str) and value and not Path(value).is_absolute() and (base_dir / value).is_file():
                    body[key] = str((base_dir / value).resolve())
    return out


def load_served(path: str | Path) -> Served:
    """The served design from a TOML file; refuses (`ConfigError`) a config `uwlab design` would refuse."""
    path = Path(path).resolve()
    base = path.parent
    raw = absolute_paths(load_raw(path), base)
    build_design(copy_raw(raw), base)
    return Served(raw, base, path)


def _table(body: dict, member: str) -> dict:
    value = body.get(member, {})
    if not isinstance(value, dict):
        raise ConfigError(member, value, "must be an object")
    return value


def design_raw(body, served: Served, extra: tuple[str, ...] = ()) -> dict:
    """The raw design config of a request body (module docstring); `extra` names the other members the request
    may have (a sweep's ``grid``), anything else is refused."""
    if not isinstance(body, dict):
        raise ConfigError("request", body, "must be a JSON object")
    allowed = BODY_MEMBERS + extra
    unknown = [k for k in body if k not in allowed]
    if unknown:
        raise ConfigError(unknown[0], body[unknown[0]], f"unknown member; allowed: {', '.join(allowed)}")
    raw = copy_raw(_table(body, "config") if "config" in body else served.raw)
    for dotted, value in _table(body, "set").items():
        _apply(raw, dotted, value)
    for dotted, text in _table(body, "text").items():
        if not isinstance(text, str):
            raise ConfigError(dotted, text, "text values must be strings (use set for JSON values)")
        _apply(raw, dotted, parse_value(text.strip()) if text.strip() else None)
    return raw


def _apply(raw: dict, dotted: str, value) -> None:
    apply_override(raw, dotted, value)
    if value is None:  # unset: the key's default applies
        section, _, key = dotted.partition(".")
        del raw[section][key]


def build(body, served: Served) -> Design:
    """The validated design of a request body (`ConfigError` naming the key, as `uwlab design` says it)."""
    return build_design(design_raw(body, served), served.base_dir)


def value_text(value) -> str:
    """A config value as ``--set`` text that `parse_value` reads back to the same value: numbers in full
    precision, bare words bare, other strings quoted, lists in TOML syntax."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        bare = value and value == value.strip() and parse_value(value) == value
        return value if bare else tomli_w.dumps({"v": value})[len("v = ") :].strip()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(value_text(v) for v in value) + "]"
    raise ConfigError("config", value, "cannot be shown as a value (a table where a value belongs?)")


def field_texts(raw: dict) -> dict[str, str]:
    """{"section.key": text} of every key of a raw config (`value_text`)."""
    return {
        f"{section}.{key}": value_text(value)
        for section, body in raw.items()
        if isinstance(body, dict)
        for key, value in body.items()
    }


def read_toml_text(text: str, name: str = "uploaded file") -> dict:
    """A design config from TOML text (an uploaded file); `ConfigError` naming the file when it does not parse."""
    if not isinstance(text, str):
        raise ConfigError("toml", text, "must be the text of a TOML file")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("toml", name, f"invalid TOML ({exc})") from None


def toml_text(raw: dict, header: str = "") -> str:
    """The TOML file of a raw config (tomli-w; floats written so that they read back bit for bit)."""
    comment = "".join(f"# {line}\n" for line in header.splitlines())
    return comment + ("\n" if comment else "") + tomli_w.dumps(raw)
