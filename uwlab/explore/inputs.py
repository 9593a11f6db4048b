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

Files a request may name (`Served.readable`, the explorer's one file boundary): only regular files of at most
`MAX_FILE_BYTES` inside the explorer's roots — ``configs/``, the served config's folder, the ``--data-dir`` folders
and the ``--profile`` files. Every value that names a file passes it before anything is opened: the file-valued
keys of a design (`FILE_KEYS`, `check_files`; a sensor profile named with or without ``.toml``, as the model reads
it, `uwlab.model.sensor.profile_path`), each value of a sweep's grid over one of them (`check_file`) and the path of
``/api/profile``. The check is on the file the model would open (`named_file`), after links, ``.``/``..`` and
trailing separators are resolved. Any other path is refused with the same line whether or not it exists, so a
request learns nothing of the machine's files, and no refused file is opened, so none is quoted.
"""

from __future__ import annotations

import stat
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import tomli_w

from uwlab.errors import ConfigError
from uwlab.model.config import apply_override, load_raw, parse_value
from uwlab.model.build import build_design
from uwlab.model.data import config_dir, resolve_path
from uwlab.model.design import Design
from uwlab.model.sensor import profile_path
from uwlab.model.spectra import NAMED_SPECTRA
from uwlab.model.target import NAMED_REFLECTANCE
from uwlab.model.water import WATER_TYPES

BODY_MEMBERS = ("config", "set", "text")
MAX_FILE_BYTES = 1_000_000
# Design keys whose string values name a file unless they are one of these names (`uwlab.model.build`); a sensor
# profile always names one (`named_file`).
FILE_KEYS = {
    "light.spectrum": NAMED_SPECTRA,
    "water.type": WATER_TYPES,
    "target.reflectance": NAMED_REFLECTANCE,
    "lens.transmittance": (),
    "sensor.profile": (),
}
OUTSIDE_ROOTS = "not a file the explorer may read (configs/, the served config's folder, --data-dir, --profile)"


def named_file(dotted: str, value: object, base: Path | None) -> Path | None:
    """The file the design key ``dotted`` = ``value`` makes `uwlab.model.build.build_design` open (relative names
    against ``base``), or None when the value names no file (a number, a named water type, spectrum or bottom).

    >>> named_file("water.type", "jerlov-I", None), named_file("lens.transmittance", 0.9, None)
    (None, None)
    >>> named_file("light.spectrum", "led.csv", Path("/data")), named_file("sensor.profile", "../x.toml", Path("/d"))
    (PosixPath('/data/led.csv'), PosixPath('/d/../x.toml'))
    """
    if not isinstance(value, str) or value in FILE_KEYS[dotted]:
        return None
    return profile_path(value, base) if dotted == "sensor.profile" else resolve_path(value, base)


@dataclass(frozen=True)
class Served:
    """The design `uwlab explore` was started with: its raw config, file and the folder relative names resolve in;
    ``roots``: the folders and files requests may name besides ``configs/`` (`readable`)."""

    raw: dict
    base_dir: Path
    path: Path | None = None
    roots: tuple[Path, ...] = ()

    def with_roots(self, *roots: str | Path) -> Served:
        """The same design with more folders or files requests may name."""
        return replace(self, roots=(*self.roots, *(Path(r).expanduser().resolve() for r in roots)))

    def readable(self, path: Path) -> Path | None:
        """``path`` with links, ``.``/``..`` and trailing separators resolved when requests may name it: inside a
        root and, if it exists, a regular file of at most `MAX_FILE_BYTES`; else None, whatever the reason (a
        missing file, a name too long, a loop of links...). A missing file inside a root is left to the loader to
        report, as `uwlab design` does. Nothing is opened."""
        try:
            path = path.resolve()
            roots = (config_dir().resolve(), self.base_dir.resolve(), *self.roots)
            if not any(path == root or path.is_relative_to(root) for root in roots):
                return None
            info = path.stat()
        except FileNotFoundError:
            return path
        except (OSError, RuntimeError, ValueError):
            return None
        return path if stat.S_ISREG(info.st_mode) and info.st_size <= MAX_FILE_BYTES else None


def check_file(dotted: str, value: object, served: Served) -> None:
    """Refuse (`ConfigError` naming the key, `OUTSIDE_ROOTS`) a value of a file-valued key (`FILE_KEYS`) naming a
    file requests may not read (module docstring); other keys and values pass."""
    if dotted not in FILE_KEYS:
        return
    path = named_file(dotted, value, served.base_dir)
    if path is not None and served.readable(path) is None:
        raise ConfigError(dotted, value, OUTSIDE_ROOTS)


def check_files(raw: dict, served: Served) -> None:
    """`check_file` on every file-valued key of a raw design config."""
    for dotted in FILE_KEYS:
        section, _, key = dotted.partition(".")
        body = raw.get(section)
        if isinstance(body, dict):
            check_file(dotted, body.get(key), served)


def copy_raw(raw: dict) -> dict:
    return {section: dict(body) if isinstance(body, dict) else body for section, body in raw.items()}


def absolute_paths(raw: dict, base_dir: Path) -> dict:
    """A copy of `raw` where each file-valued key (`FILE_KEYS`) naming a file relative to `base_dir` names it by
    its absolute path (names such as ``jerlov-I`` or ``imx250m`` stay as they are). Nothing on disk is looked at."""
    out = copy_raw(raw)
    for dotted in FILE_KEYS:
        section, _, key = dotted.partition(".")
        body = out.get(section)
        if not isinstance(body, dict) or not isinstance(value := body.get(key), str):
            continue
        if named_file(dotted, value, base_dir) == base_dir / value != Path(value):
            body[key] = str(base_dir / value)
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
    check_files(raw, served)
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


def read_toml_text(text: object, name: str = "uploaded file") -> dict:
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
