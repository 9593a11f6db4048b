"""Errors shared by every layer.

`UwlabError` is the one exception the CLI turns into a one-line message and exit code 2.
Raise it (or a subclass) for bad input: it names the offending key and value.
"""

from __future__ import annotations


class UwlabError(Exception):
    """Bad input or an unrecoverable condition, reported to the user in one line."""


MAX_SHOWN_CHARS = 120


def shown(value: object) -> str:
    """A value as an error line quotes it: its repr, cut to `MAX_SHOWN_CHARS` (a 50 MB input is not echoed back).

    >>> shown("x" * 200)[-14:], len(shown("x" * 200))
    ('x… (202 chars)', 133)
    """
    text = repr(value)
    return text if len(text) <= MAX_SHOWN_CHARS else f"{text[:MAX_SHOWN_CHARS]}… ({len(text)} chars)"


def said(exc: BaseException) -> str:
    """What a library's exception says, for an error line: its message on one line; when the library packed a
    formatted traceback into the message (pyvisa-sim re-raises a definitions file it cannot read that way, twice for
    a malformed YAML), the first exception it was handling that says something else.

    >>> try:
    ...     try:
    ...         open("/no/such.yaml")
    ...     except OSError as exc:
    ...         raise ValueError("Could not parse. 'Traceback (most recent call last):\\n  File ...'")
    ... except ValueError as exc:
    ...     said(exc)
    "[Errno 2] No such file or directory: '/no/such.yaml'"
    """
    text = str(exc)
    while "Traceback (most recent call last)" in text and exc.__context__ is not None:  # packed again and again
        exc = exc.__context__
        text = str(exc)
    return " ".join(text.split())


class ConfigError(UwlabError, ValueError):
    """A configuration key has a wrong, missing or out-of-range value."""

    def __init__(self, key: str, value: object, reason: str):
        self.key = key
        self.value = value
        self.reason = reason
        super().__init__(f"{key} = {shown(value)}: {reason}")


class DeviceError(UwlabError):
    """A device (camera, light, spectrometer) failed or is unavailable."""
