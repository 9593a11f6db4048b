"""A small SCPI program-message parser for the simulated instruments: headers, parameters and the error queue.

Written from SCPI-1999 Volume 1 (SCPI Consortium, "Standard Commands for Programmable Instruments", 1999):

- §6.2 "Program headers": each keyword has a short form (its upper-case letters) and a long form (the whole word);
  a parser accepts exactly those two, in any case (``CURR``, ``curr``, ``Current``; not ``CURRE``); nodes in square
  brackets are optional; a numeric suffix of 1 may be omitted (``SOURce[1]``, ``OUTPut[1]``). A leading ``:`` names
  the root.
- §6.2.3 (and IEEE 488.2 §7.1): several program message units in one message are separated by ``;``; each unit here
  is parsed from the root, as if it began with ``:`` (what a sender that always writes full headers gets from any
  parser); the responses to the queries among them are returned in one line separated by ``;``.
- §7 "Parameters" (and IEEE 488.2 §7.7): numeric values in decimal or exponent form, with an optional unit suffix
  (``V``, ``mV``, ``A``, ``mA``), or ``MINimum``/``MAXimum``/``DEFault``; booleans ``ON``/``OFF``/``1``/``0``.
- Volume 2 §21.8 (``SYSTem:ERRor[:NEXT]?``) and IEEE 488.2 §11.5: a first-in first-out error queue; when it is full
  the newest entry is replaced by ``-350,"Queue overflow"``; read when empty it returns ``0,"No error"``. The
  error numbers used are SCPI-1999 Vol. 2 §21.8's: -100 command errors (-104 data type error, -108 parameter not
  allowed, -109 missing parameter, -113 undefined header), -200 execution errors (-221 settings conflict, -222 data
  out of range, -223 too much data, -224 illegal parameter value), -300 device-specific errors, -350 queue overflow.
"""

from __future__ import annotations

import re
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

ERROR_MESSAGES = {
    -100: "Command error",
    -104: "Data type error",
    -108: "Parameter not allowed",
    -109: "Missing parameter",
    -113: "Undefined header",
    -221: "Settings conflict",
    -222: "Data out of range",
    -223: "Too much data",
    -224: "Illegal parameter value",
    -300: "Device-specific error",
    -350: "Queue overflow",
}
ERROR_QUEUE_LENGTH = 20  # assumed: Keysight's E36100 and most SCPI supplies keep 20 errors
UNITS = {"": 1.0, "V": 1.0, "MV": 1e-3, "A": 1.0, "MA": 1e-3, "UA": 1e-6}
_NUMBER = re.compile(r"^([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-z]*)$")
_KEYWORD = re.compile(r"([A-Z]+)([a-z]*)(\d*)(#?)")


class ScpiError(Exception):
    """An error the instrument puts in its queue: ``code`` and the SCPI message (plus an optional detail)."""

    def __init__(self, code: int, detail: str = ""):
        self.code = code
        message = ERROR_MESSAGES.get(code, "Error")
        self.text = f"{message}; {detail}" if detail else message
        super().__init__(f"{code},{self.text}")


def header_pattern(spec: str) -> re.Pattern[str]:
    """A regular expression for a SCPI header written as the manuals write it.

    ``spec`` uses the manuals' notation: keywords in mixed case (upper case = short form), optional nodes in
    ``[...]``, ``#`` after a keyword for an optional numeric suffix 1 (``SOURce#`` = ``SOUR``, ``SOUR1``,
    ``SOURCE``, ``SOURCE1``), a digit for a required suffix (``SENSe3``), ``?`` at the end of a query. The
    pattern matches a whole header, with or without its leading ``:``, in any case.

    >>> bool(header_pattern("[SOURce#:]CURRent[:LEVel]?").match("sour1:current:lev?"))
    True
    >>> bool(header_pattern("[SOURce#:]CURRent[:LEVel]?").match("CURRE?"))
    False
    """

    def keyword(match: re.Match[str]) -> str:
        short, rest, digits, optional_one = match.groups()
        forms = f"(?:{short}{rest.upper()}|{short})" if rest else short
        return forms + digits + ("1?" if optional_one else "")

    body = spec.replace("?", "\\?").replace("[", "(?:").replace("]", ")?").replace("*", "\\*")
    return re.compile("^:?" + _KEYWORD.sub(keyword, body) + "$", re.IGNORECASE)


def parse_number(argument: str, minimum: float, maximum: float, default: float | None = None) -> float:
    """A numeric parameter in [minimum, maximum] (MIN/MAX/DEF as their values); -104 or -222 otherwise."""
    word = argument.strip().upper()
    if word in ("MIN", "MINIMUM"):
        return minimum
    if word in ("MAX", "MAXIMUM"):
        return maximum
    if word in ("DEF", "DEFAULT") and default is not None:
        return default
    match = _NUMBER.match(argument.strip())
    if match is None or match.group(2).upper() not in UNITS:
        raise ScpiError(-104, f"not a number: {argument.strip()[:32]}")
    value = float(match.group(1)) * UNITS[match.group(2).upper()]
    if not minimum <= value <= maximum:
        raise ScpiError(-222, f"{value:g} outside [{minimum:g}, {maximum:g}]")
    return value


def parse_bool(argument: str) -> bool:
    """``ON``/``OFF``/``1``/``0`` (any case); -224 otherwise."""
    word = argument.strip().upper()
    if word in ("ON", "1"):
        return True
    if word in ("OFF", "0"):
        return False
    raise ScpiError(-224, f"expected ON, OFF, 1 or 0, got {argument.strip()[:32]}")


def expect_arguments(arguments: list[str], count: int) -> list[str]:
    """``arguments`` if there are exactly ``count``; -109 (too few) or -108 (too many) otherwise."""
    if len(arguments) < count:
        raise ScpiError(-109)
    if len(arguments) > count:
        raise ScpiError(-108)
    return arguments


Handler = Callable[[list[str]], "str | None"]


@dataclass(frozen=True)
class Command:
    """One header (its compiled pattern and the manual's spelling) and what answers it."""

    spec: str
    pattern: re.Pattern[str]
    handler: Handler


def command_table(entries: list[tuple[str, Handler]]) -> list[Command]:
    return [Command(spec, header_pattern(spec), handler) for spec, handler in entries]


class ErrorQueue:
    """SCPI's first-in first-out error queue (see the module docstring), with the IEEE 488.2 event bits."""

    def __init__(self, length: int = ERROR_QUEUE_LENGTH):
        self.length = length
        self.entries: deque[tuple[int, str]] = deque()
        self.event_status = 0  # IEEE 488.2 §11.5.1 Standard Event Status Register

    def push(self, error: ScpiError) -> None:
        # IEEE 488.2 §11.5.1.1: -100s set CME (bit 5), -200s EXE (bit 4), -300s DDE (bit 3), -400s QYE (bit 2).
        self.event_status |= {1: 32, 2: 16, 3: 8, 4: 4}.get(abs(error.code) // 100, 0)
        if len(self.entries) >= self.length:
            self.entries[-1] = (-350, ERROR_MESSAGES[-350])
            return
        self.entries.append((error.code, error.text))

    def pop(self) -> tuple[int, str]:
        return self.entries.popleft() if self.entries else (0, "No error")

    def clear(self) -> None:
        self.entries.clear()
        self.event_status = 0


def split_units(line: str) -> list[str]:
    """A program message split into its units at the ``;`` outside quoted strings."""
    units: list[str] = []
    current: list[str] = []
    quote = ""
    for char in line:
        if quote:
            quote = "" if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char == ";":
            units.append("".join(current))
            current = []
            continue
        current.append(char)
    units.append("".join(current))
    return [unit.strip() for unit in units if unit.strip()]


def split_unit(unit: str) -> tuple[str, list[str]]:
    """A program message unit's header and its comma-separated parameters."""
    header, _, rest = unit.partition(" ")
    if "\t" in header:
        header, _, more = header.partition("\t")
        rest = more + " " + rest
    rest = rest.strip()
    return header, [argument.strip() for argument in rest.split(",")] if rest else []


def execute(commands: list[Command], queue: ErrorQueue, line: str) -> str | None:
    """Run one program message; the responses of its queries joined by ``;`` (None if it had none).

    A command error (-1xx) discards the rest of the message, as IEEE 488.2 §6.1.6.1.1 has a parser do; an
    execution error (-2xx, -3xx) is queued and the next unit runs."""
    responses = []
    for unit in split_units(line):
        header, arguments = split_unit(unit)
        command = next((c for c in commands if c.pattern.match(header)), None)
        try:
            if command is None:
                raise ScpiError(-113, header[:32])
            response = command.handler(arguments)
        except ScpiError as error:
            queue.push(error)
            if error.code > -200:
                break
            continue
        if response is not None:
            responses.append(response)
    return ";".join(responses) if responses else None
