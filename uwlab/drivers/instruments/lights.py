"""Open a light by its instrument definition, whatever its adapter: VISA (`VisaLight`) or a serial line
(`SerialLight`)."""

from __future__ import annotations

from uwlab.drivers.instruments.definition import SerialLightDefinition, load_any_light_definition
from uwlab.drivers.instruments.serial_light import SerialLight
from uwlab.drivers.instruments.visa_light import VisaLight, open_visa_light
from uwlab.errors import ConfigError


def open_light_instrument(
    instrument: str,
    resource: str,
    visa_library: str | None = None,
    max_drive: float | None = None,
    forward_voltage_v: float | None = None,
    identity_contains: tuple[str, ...] = (),
) -> VisaLight | SerialLight:
    """The light `instrument` (a name in configs/instruments/ or a file) on `resource`: a VISA resource for a VISA
    definition (`visa_library` as PyVISA takes it; `max_drive` the rig's maximum drive, `forward_voltage_v` its
    LED's maximum forward voltage, `identity_contains` words its ``*IDN?`` must contain: `LightRig`), a serial port
    for a serial one (whose level is its drive: none of these applies). `ConfigError`/`DeviceError` in one line
    otherwise."""
    definition = load_any_light_definition(instrument)
    if not isinstance(definition, SerialLightDefinition):
        return open_visa_light(instrument, resource, visa_library, max_drive, forward_voltage_v, identity_contains)
    if visa_library is not None:
        raise ConfigError("visa-library", visa_library, f"{instrument} is a serial instrument, not a VISA one")
    if max_drive is not None:
        raise ConfigError("max_current_a", max_drive, f"{instrument} is dimmed by level, it has no drive current")
    if forward_voltage_v is not None:
        raise ConfigError("forward_voltage_v", forward_voltage_v, f"{instrument} is dimmed by level, not a supply")
    if identity_contains:
        raise ConfigError("identity_contains", list(identity_contains), f"{instrument} is a serial instrument")
    return SerialLight(definition, instrument, resource)
