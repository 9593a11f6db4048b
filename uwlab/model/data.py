"""Locating and reading the data files of `configs/` (tables in CSV, profiles in TOML).

The configuration directory is `$UWLAB_CONFIG_DIR` if set, else the `configs/` folder beside the package.
Relative paths in a config file are resolved against that file's folder. CSV files may start with `#` comment
lines (their provenance header); read with the standard library's `csv` (no pandas: the design path stays light).

This is also the one file boundary of every input uwlab reads (configs, plans, spectra, descriptors, calibration
files, dataset documents, images): `read_bytes` (and `read_text`, `read_json`, `read_toml` on it) reads regular files
only, bounded; `check_input_file` applies the same rule to a path a library opens itself (OpenCV, tifffile,
pyarrow). A FIFO, a device or an over-size file is a one-line `ConfigError`, never waited on or read.
"""

from __future__ import annotations

import csv
import json
import math
import os
import stat
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from uwlab.errors import ConfigError


def config_dir() -> Path:
    env = os.environ.get("UWLAB_CONFIG_DIR")
    return Path(env) if env else Path(__file__).resolve().parents[2] / "configs"


MAX_TOML_BYTES = 10_000_000
MAX_CSV_BYTES = 100_000_000
# No physical table of uwlab (wavelengths, spectra, QE, attenuation, counts) comes near this magnitude: a larger
# value is a wrong unit or a corrupt file, and squaring it would overflow float64 downstream.
MAX_ABS_VALUE = 1e15


# Images and Parquet tables: a 16-bit frame of 1e9 px is beyond any camera uwlab drives
MAX_BINARY_BYTES = 2_000_000_000
MAX_JSON_BYTES = 100_000_000


def check_input_file(path: str | os.PathLike[str], key: str, max_bytes: int, kind: str) -> Path:
    """``path``, checked as every input file uwlab reads is: it exists and is a regular file of at most
    ``max_bytes``. A directory, a device (``/dev/zero``), a FIFO (opening it would block) or an oversized file is a
    `ConfigError` naming ``key`` and the file, found by ``stat`` without opening it. For a path handed to a library
    that opens it itself (OpenCV, tifffile); uwlab's own reads go through `read_bytes`."""
    path = Path(path)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise ConfigError(key, str(path), "file not found") from None
    except OSError as exc:
        raise ConfigError(key, str(path), f"cannot be read ({exc.strerror})") from None
    _check_stat(info, path, key, max_bytes, kind)
    return path


def _check_stat(info: os.stat_result, path: Path, key: str, max_bytes: int, kind: str) -> None:
    article = "an" if kind[:1].lower() in "aeio" else "a"
    if stat.S_ISDIR(info.st_mode):
        raise ConfigError(key, str(path), f"is a directory, not {article} {kind} file")
    if not stat.S_ISREG(info.st_mode):
        raise ConfigError(key, str(path), f"not a regular file (a device or pipe), not {article} {kind} file")
    if info.st_size > max_bytes:
        raise ConfigError(
            key, str(path), f"{info.st_size} bytes: larger than any {kind} file uwlab reads ({max_bytes} bytes)"
        )


def read_bytes(path: str | os.PathLike[str], key: str, max_bytes: int, kind: str) -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` (`check_input_file`'s rule). The file is opened
    non-blocking and checked again on the open descriptor (a path swapped for a FIFO or device between the two is
    refused, not waited on), and at most ``max_bytes`` are read whatever its size claims."""
    path = check_input_file(path, key, max_bytes, kind)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except PermissionError:
        raise ConfigError(key, str(path), "cannot be read (permission denied)") from None
    except OSError as exc:
        raise ConfigError(key, str(path), f"cannot be read ({exc.strerror})") from None
    try:
        _check_stat(os.fstat(fd), path, key, max_bytes, kind)
        chunks, size = [], 0
        while size <= max_bytes and (chunk := os.read(fd, min(1 << 24, max_bytes + 1 - size))):
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise ConfigError(key, str(path), f"cannot be read ({exc.strerror})") from None
    finally:
        os.close(fd)
    if size > max_bytes:
        raise ConfigError(key, str(path), f"grew beyond {max_bytes} bytes while read: larger than any {kind} file")
    return b"".join(chunks)


def read_text(path: str | os.PathLike[str], key: str, max_bytes: int, kind: str) -> str:
    """The UTF-8 text of a regular file of at most ``max_bytes`` (`read_bytes`); a file that is not UTF-8 is a
    `ConfigError` naming ``key`` and the file."""
    data = read_bytes(path, key, max_bytes, kind)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        bom = " (a UTF-16 byte-order mark: save it as UTF-8)" if data[:2] in (b"\xff\xfe", b"\xfe\xff") else ""
        raise ConfigError(key, str(path), f"not UTF-8 text: byte {exc.start} is {data[exc.start]:#04x}{bom}") from None


def read_json(path: str | os.PathLike[str], key: str, kind: str = "JSON") -> Any:
    """A JSON document (`read_text`'s checks first); `ConfigError` naming ``key`` and the file when it does not
    parse."""
    text = read_text(path, key, MAX_JSON_BYTES, kind)
    try:
        return json.loads(text)
    except ValueError as exc:
        raise ConfigError(key, str(path), f"invalid JSON ({exc})") from None


def read_toml(path: Path, key: str = "config") -> dict:
    """A TOML file (`read_text`'s checks first); `ConfigError` naming ``key`` and the file when it does not parse."""
    text = read_text(path, key, MAX_TOML_BYTES, "TOML")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(key, str(path), f"invalid TOML ({exc})") from None


def csv_rows(path: Path, key: str) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """The header and the (line number, stripped fields) of each row of a CSV. Text from ``#`` to the end of a line
    is a comment; blank lines are skipped; the first other line names the columns; every row has one field per
    column."""
    text = read_text(path, key, MAX_CSV_BYTES, "CSV")
    lines = [(number, line.split("#", 1)[0]) for number, line in enumerate(text.splitlines(), 1)]
    lines = [(number, line) for number, line in lines if line.strip()]
    if not lines:
        raise ConfigError(key, str(path), "unreadable CSV (no header line)")
    rows = csv.reader(line for _, line in lines)
    header = [name.strip() for name in next(rows)]
    out = []
    for (number, _), row in zip(lines[1:], rows, strict=True):
        if len(row) != len(header):
            raise ConfigError(key, str(path), f"line {number} has {len(row)} fields, the header {len(header)}")
        out.append((number, [cell.strip() for cell in row]))
    return header, out


def read_csv_columns(path: Path, columns: tuple[str, ...], key: str) -> dict[str, np.ndarray]:
    """Read named numeric columns of a CSV, sorted by the first. Every value must be a finite number of magnitude
    at most `MAX_ABS_VALUE`; a `ConfigError` names the file, the line and the column of the first that is not. A
    first-column value (a wavelength) given twice with different values is refused (`sorted_unique`); a row
    repeated exactly is read once."""
    header, rows = csv_rows(path, key)
    missing = [c for c in columns if c not in header]
    if missing:
        raise ConfigError(key, str(path), f"missing column(s) {', '.join(missing)}; has {', '.join(header)}")
    index = [header.index(c) for c in columns]
    values = np.empty((len(rows), len(columns)))
    for r, (number, row) in enumerate(rows):
        for j, (i, name) in enumerate(zip(index, columns, strict=True)):
            cell = row[i]
            if cell == "":
                raise ConfigError(key, str(path), f"line {number}: empty cell in column {name}")
            try:
                value = float(cell)
            except ValueError:
                hint = " (a decimal comma? write 0.5, not 0,5)" if "," in cell else ""
                raise ConfigError(key, str(path), f"line {number}: {name} = {cell!r} is not a number{hint}") from None
            if not math.isfinite(value) or abs(value) > MAX_ABS_VALUE:
                raise ConfigError(
                    key,
                    str(path),
                    f"line {number}: {name} = {cell} is not a finite number of "
                    f"magnitude ≤ {MAX_ABS_VALUE:g} — is the unit right?",
                )
            values[r, j] = value
    values = sorted_unique(values, [number for number, _ in rows], path, key, columns)
    return {c: values[:, j] for j, c in enumerate(columns)}


def sorted_unique(values: np.ndarray, lines: list[int], path: Path, key: str, columns: tuple[str, ...]) -> np.ndarray:
    """The rows of ``values`` (one per line of ``path``, numbered ``lines``) sorted by the first column, a row
    repeated exactly kept once. A first-column value (a wavelength) on two lines with different values in the
    other columns is a `ConfigError` naming the file, the value and both lines: which of the two is meant cannot
    be known, and taking either silently would hide a mistake in the file."""
    order = np.argsort(values[:, 0], kind="stable")
    values = values[order]
    same_first = values[1:, 0] == values[:-1, 0]
    conflict = np.flatnonzero(same_first & np.any(values[1:] != values[:-1], axis=1))
    if conflict.size:
        i = int(conflict[0])
        first, second = sorted((lines[order[i]], lines[order[i + 1]]))
        raise ConfigError(
            key,
            str(path),
            f"{columns[0]} = {values[i, 0]:g} is given twice with different values (lines {first} and {second})",
        )
    return values[np.concatenate([[True], ~same_first])] if len(values) else values


def resolve_path(value: str, base: Path | None) -> Path:
    path = Path(value).expanduser()
    if not path.is_absolute() and base is not None:
        path = base / path
    return path
