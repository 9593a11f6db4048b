"""Locating and reading the data files of `configs/` (tables in CSV, profiles in TOML).

The configuration directory is `$UWLAB_CONFIG_DIR` if set, else the `configs/` folder beside the package.
Relative paths in a config file are resolved against that file's folder. CSV files may start with `#` comment
lines (their provenance header).
"""
from __future__ import annotations

import os
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd

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


def read_csv_columns(path: Path, columns: tuple[str, ...], key: str) -> dict[str, np.ndarray]:
    """Read named numeric columns of a CSV, sorted by the first, duplicate first-column values dropped."""
    try:
        frame = pd.read_csv(path, comment="#")
    except FileNotFoundError:
        raise ConfigError(key, str(path), "file not found") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise ConfigError(key, str(path), f"unreadable CSV ({exc})") from None
    frame.columns = [str(c).strip() for c in frame.columns]
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise ConfigError(key, str(path), f"missing column(s) {', '.join(missing)}; has {', '.join(frame.columns)}")
    try:
        frame = frame[list(columns)].astype(float)
    except ValueError as exc:
        raise ConfigError(key, str(path), f"non-numeric value ({exc})") from None
    if frame.isna().any().any():
        raise ConfigError(key, str(path), "empty cells")
    frame = frame.sort_values(columns[0]).drop_duplicates(columns[0])
    return {c: frame[c].to_numpy() for c in columns}


def resolve_path(value: str, base: Path | None) -> Path:
    path = Path(value).expanduser()
    if not path.is_absolute() and base is not None:
        path = base / path
    return path
