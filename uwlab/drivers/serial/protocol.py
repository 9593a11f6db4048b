"""The ``uwlab-ascii`` line protocol: reply grammar and pure parsers (see docs/serial-protocol.md).

Every reply is one ASCII line terminated by ``\\n`` (a preceding ``\\r`` is accepted):

- ``OK`` — a setting command was applied;
- ``ERR <code> <message>`` — the command failed (codes in `ERROR_CODES`);
- ``# <text>`` — a banner, sent by the instrument after a reset (``*RST`` or spontaneous);
- anything else printable — the value of a query.

``SPEC:READ?`` replies with a block: ``BEGIN <n> <saturated 0|1>``, then ``n`` lines
``<wavelength_nm> <irradiance_w_m2_nm>``, then ``END``.

The parsers are pure and raise only `ReplyParseError`, whatever bytes they are given.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

TERMINATOR = b"\n"
BANNER_PREFIX = "#"
BLOCK_BEGIN = "BEGIN"
BLOCK_END = "END"
MAX_LINE_BYTES = 4096

ERR_UNKNOWN_COMMAND = 100
ERR_BAD_ARGUMENT = 101
ERR_OUT_OF_RANGE = 102
ERR_BUSY = 200
ERR_HARDWARE = 300
ERROR_CODES = {
    ERR_UNKNOWN_COMMAND: "unknown command",
    ERR_BAD_ARGUMENT: "malformed argument",
    ERR_OUT_OF_RANGE: "argument out of range",
    ERR_BUSY: "busy, retry later",
    ERR_HARDWARE: "hardware fault",
}
RETRYABLE_ERROR_CODES = frozenset({ERR_BUSY})


class ReplyParseError(ValueError):
    """A reply line that is not valid ``uwlab-ascii`` (garbage, truncated or of the wrong type)."""


@dataclass(frozen=True)
class Reply:
    """One parsed reply line: ``kind`` is ``ok``, ``value``, ``error`` or ``banner``."""

    kind: str
    text: str = ""
    code: int = 0


def decode_line(raw: bytes) -> str:
    """ASCII text of one line without its terminator; refuses control characters and non-ASCII bytes."""
    body = raw[:-1] if raw.endswith(TERMINATOR) else raw
    body = body[:-1] if body.endswith(b"\r") else body
    if len(body) > MAX_LINE_BYTES:
        raise ReplyParseError(f"line longer than {MAX_LINE_BYTES} bytes")
    if any(b < 0x20 or b > 0x7E for b in body):
        raise ReplyParseError(f"non-printable bytes in reply {body[:40]!r}")
    text = body.decode("ascii").strip()
    if not text:
        raise ReplyParseError("empty reply line")
    return text


def parse_reply(raw: bytes) -> Reply:
    """Classify one reply line (with or without its terminator)."""
    text = decode_line(raw)
    if text == "OK":
        return Reply("ok")
    if text.startswith(BANNER_PREFIX):
        return Reply("banner", text[len(BANNER_PREFIX) :].strip())
    if text == "ERR" or text.startswith("ERR "):
        code, _, message = text[4:].strip().partition(" ")
        if not re.fullmatch(r"[0-9]{1,4}", code):
            raise ReplyParseError(f"malformed error reply {text!r}")
        return Reply("error", message.strip(), int(code))
    return Reply("value", text)


def parse_float(text: str) -> float:
    """A finite decimal number."""
    try:
        value = float(text)
    except ValueError:
        raise ReplyParseError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise ReplyParseError(f"expected a finite number, got {text!r}")
    return value


def parse_int(text: str) -> int:
    """A decimal integer."""
    if not re.fullmatch(r"-?[0-9]{1,12}", text):
        raise ReplyParseError(f"expected an integer, got {text!r}")
    return int(text)


def parse_bool(text: str) -> bool:
    """``1`` / ``0`` (also ``ON`` / ``OFF``)."""
    value = {"1": True, "ON": True, "0": False, "OFF": False}.get(text.upper())
    if value is None:
        raise ReplyParseError(f"expected 0 or 1, got {text!r}")
    return value


def parse_block_header(text: str) -> tuple[int, bool]:
    """``BEGIN <n> <saturated>`` → (number of data lines, saturated flag)."""
    fields = text.split()
    if len(fields) != 3 or fields[0] != BLOCK_BEGIN:
        raise ReplyParseError(f"expected 'BEGIN <n> <saturated>', got {text!r}")
    n = parse_int(fields[1])
    if not 0 < n <= 100_000:
        raise ReplyParseError(f"implausible spectrum length {n}")
    return n, parse_bool(fields[2])


def parse_spectrum_lines(lines: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """``<wavelength_nm> <irradiance_w_m2_nm>`` lines → arrays; wavelengths must strictly increase."""
    pairs = []
    for line in lines:
        fields = line.split()
        if len(fields) != 2:
            raise ReplyParseError(f"expected '<wavelength_nm> <irradiance>', got {line!r}")
        pairs.append((parse_float(fields[0]), parse_float(fields[1])))
    data = np.array(pairs, dtype=float).reshape(-1, 2)
    if len(data) == 0 or np.any(np.diff(data[:, 0]) <= 0):
        raise ReplyParseError("spectrum wavelengths are empty or not strictly increasing")
    return data[:, 0], data[:, 1]


def format_float(value: float) -> str:
    """The protocol's number format: shortest round-tripping decimal."""
    return repr(float(value))
