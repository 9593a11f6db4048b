"""Errors shared by every layer.

`UwlabError` is the one exception the CLI turns into a one-line message and exit code 2.
Raise it (or a subclass) for bad input: it names the offending key and value.
"""

from __future__ import annotations


class UwlabError(Exception):
    """Bad input or an unrecoverable condition, reported to the user in one line."""


class ConfigError(UwlabError, ValueError):
    """A configuration key has a wrong, missing or out-of-range value."""

    def __init__(self, key: str, value: object, reason: str):
        self.key = key
        self.value = value
        self.reason = reason
        super().__init__(f"{key} = {value!r}: {reason}")


class DeviceError(UwlabError):
    """A device (camera, light, spectrometer) failed or is unavailable."""
