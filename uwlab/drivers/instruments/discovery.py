"""Instruments a lab can reach: VISA resources (with their ``*IDN?``) and serial ports, for ``uwlab devices``.

Each is a `Found` row of the same shape as a camera's (backend, id, vendor, model, serial): ``visa`` rows are
PyVISA's resources (``visa_library``: ``@py`` by default, ``PATH.yaml@sim`` for pyvisa-sim, a vendor VISA's path),
vendor/model/serial taken from the first three fields of ``*IDN?`` where the instrument answers within
`IDN_TIMEOUT_MS`; ``serial`` rows are the machine's serial ports (pyserial), described by their USB descriptors.
Serial VISA resources (``ASRL...``) are listed but not sent ``*IDN?``: an unknown device on a serial line may take
the bytes for something else.
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass
from typing import Any

from uwlab.errors import ConfigError, said
from uwlab.model.data import MAX_TOML_BYTES, check_input_file

IDN_TIMEOUT_MS = 500


@dataclass(frozen=True)
class Found:
    """One instrument or port: ``backend`` (``visa`` or ``serial``), ``id`` (the resource or device path)."""

    backend: str
    id: str
    vendor: str | None = None
    model: str | None = None
    serial: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def identity_fields(idn: str) -> tuple[str | None, str | None, str | None]:
    """(maker, model, serial) from an IEEE 488.2 ``*IDN?`` answer (``maker,model,serial,firmware``).

    >>> identity_fields("Keysight Technologies,E36103A,MY00000001,1.0.3-1.0.3")
    ('Keysight Technologies', 'E36103A', 'MY00000001')
    >>> identity_fields("UWLAB,SIM-LIGHT")
    ('UWLAB', 'SIM-LIGHT', None)
    """
    fields = [field.strip() or None for field in idn.split(",")] + [None, None, None]
    return fields[0], fields[1], fields[2]


def check_visa_library(visa_library: str | None) -> None:
    """A pyvisa-sim definitions file (``PATH.yaml@sim``) checked as every input file is (`check_input_file`),
    without opening it; other libraries are PyVISA's to find."""
    path, at, backend = (visa_library or "").rpartition("@")
    if at and backend == "sim" and path:
        check_input_file(path, "visa-library", MAX_TOML_BYTES, "pyvisa-sim YAML")


def visa_manager(visa_library: str | None) -> Any:
    """PyVISA's resource manager for ``visa_library`` (``@py`` when None). A pyvisa-sim definitions file
    (``PATH.yaml@sim``), which pyvisa-sim opens and reads itself, is checked first (`check_visa_library`: a FIFO,
    a device or an over-size file is refused in one line, never opened). A library
    that does not load is a `ConfigError` naming it: pyvisa-sim re-raises whatever its YAML parser raised (a
    ``yaml.ParserError`` for a malformed file) with the traceback packed into the message, `said` unpacks it."""
    import pyvisa

    check_visa_library(visa_library)
    try:
        return pyvisa.ResourceManager(visa_library or "@py")
    except Exception as exc:  # any library's own failure to load, in one line
        raise ConfigError("visa-library", visa_library, f"cannot be loaded ({said(exc)})") from None


def visa_resources(visa_library: str | None = None) -> list[Found]:
    """Every VISA resource PyVISA finds through ``visa_library``, with its ``*IDN?`` where it answers. A library
    that cannot be loaded raises `OSError`/`ValueError` (the caller reports it)."""
    with warnings.catch_warnings():  # pyvisa-py's notes on optional discovery packages (zeroconf, pyusb)
        warnings.simplefilter("ignore")
        manager = visa_manager(visa_library)
        try:
            names = manager.list_resources("?*")
            return [_resource(manager, name) for name in names]
        finally:
            manager.close()


def _resource(manager: Any, name: str) -> Found:
    import pyvisa

    if name.upper().startswith("ASRL"):
        return Found("visa", name)
    try:
        handle = manager.open_resource(name, timeout=IDN_TIMEOUT_MS, read_termination="\n", write_termination="\n")
    except (OSError, ValueError, pyvisa.errors.Error):
        return Found("visa", name)
    try:
        return Found("visa", name, *identity_fields(str(handle.query("*IDN?")).strip()))
    except (OSError, ValueError, pyvisa.errors.Error):
        return Found("visa", name)
    finally:
        handle.close()


def serial_ports() -> list[Found]:
    """The machine's serial ports (pyserial's ``comports``), with their USB maker, product and serial number."""
    from serial.tools import list_ports

    return [
        Found(
            "serial",
            port.device,
            port.manufacturer,
            port.product or (port.description if port.description not in ("n/a", port.device) else None),
            port.serial_number,
        )
        for port in sorted(list_ports.comports(), key=lambda p: p.device)
    ]
