"""Locating and reading the data files of `configs/` (tables in CSV, profiles in TOML).

The configuration directory is `$UWLAB_CONFIG_DIR` if set, else the `configs/` folder beside the package.
Relative paths in a config file are resolved against that file's folder. CSV files may start with `#` comment
lines (their provenance header); read with the standard library's `csv` (no pandas: the design path stays light).
"""

from __future__ import annotations

import csv
import os
import tomllib
from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError


def config_dir() -> Path:
    env = os.environ.get("UWLAB_CONFIG_DIR")
    return Path(env) if env else Path(__file__).resolve().parents[2] / "configs"


def read_toml(path: Path, key: str = "config") -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(key, str(path), "file not found") from None
    except IsADirectoryError:
        raise ConfigError(key, str(path), "is a directory, not a TOML file") from None
    except PermissionError:
        raise ConfigError(key, str(path), "cannot be read (permission denied)") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(key, str(path), f"invalid TOML ({exc})") from None


def read_csv_table(path: Path, key: str) -> dict[str, list[str]]:
    """The columns of a CSV file by name, as lists of stripped strings. Text from ``#`` to the end of a line is a
    comment; blank lines are skipped; the first other line names the columns; every row has one field per column."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            lines = [(number, line.split("#", 1)[0]) for number, line in enumerate(fh, 1)]
    except FileNotFoundError:
        raise ConfigError(key, str(path), "file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(key, str(path), f"unreadable CSV ({exc})") from None
    lines = [(number, line) for number, line in lines if line.strip()]
    if not lines:
        raise ConfigError(key, str(path), "unreadable CSV (no header line)")
    rows = csv.reader(line for _, line in lines)
    header = [name.strip() for name in next(rows)]
    columns: dict[str, list[str]] = {name: [] for name in header}
    for (number, _), row in zip(lines[1:], rows, strict=True):
        if len(row) != len(header):
            raise ConfigError(key, str(path), f"line {number} has {len(row)} fields, the header {len(header)}")
        for name, cell in zip(header, row, strict=True):
            columns[name].append(cell.strip())
    return columns


def read_csv_columns(path: Path, columns: tuple[str, ...], key: str) -> dict[str, np.ndarray]:
    """Read named numeric columns of a CSV, sorted by the first, duplicate first-column values dropped (the first
    kept)."""
    table = read_csv_table(path, key)
    missing = [c for c in columns if c not in table]
    if missing:
        raise ConfigError(key, str(path), f"missing column(s) {', '.join(missing)}; has {', '.join(table)}")
    if any(cell == "" for c in columns for cell in table[c]):
        raise ConfigError(key, str(path), "empty cells")
    try:
        values = {c: np.array([float(cell) for cell in table[c]]) for c in columns}
    except ValueError as exc:
        raise ConfigError(key, str(path), f"non-numeric value ({exc})") from None
    if any(np.isnan(v).any() for v in values.values()):
        raise ConfigError(key, str(path), "empty cells")
    order = np.argsort(values[columns[0]], kind="stable")
    first = values[columns[0]][order]
    keep = order[np.concatenate([[True], first[1:] != first[:-1]])] if first.size else order
    return {c: v[keep] for c, v in values.items()}


def resolve_path(value: str, base: Path | None) -> Path:
    path = Path(value).expanduser()
    if not path.is_absolute() and base is not None:
        path = base / path
    return path
