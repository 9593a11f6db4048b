"""Lab instruments declared in files: a light (LED driver, programmable DC supply) over VISA through PyVISA.

An instrument definition (``configs/instruments/NAME.toml``, `definition`) names the adapter, the command strings,
the limits and how a light level in [0, 1] maps to the drive; `VisaLight` drives any such instrument through a
PyVISA resource (the pure-Python ``@py`` backend by default; a vendor VISA or ``PATH.yaml@sim``, pyvisa-sim, with
``visa_library``); `SerialLight` one on a serial line speaking ``uwlab-ascii`` (``adapter = "serial"``);
`open_light_instrument` opens either by its definition. A new instrument of a known family is a new definition
file, no Python (docs/instruments.md).
"""

from __future__ import annotations

from uwlab.drivers.instruments.definition import (
    LightDefinition,
    LightRig,
    SerialLightDefinition,
    load_any_light_definition,
    load_light_definition,
    load_light_rig,
)
from uwlab.drivers.instruments.lights import open_light_instrument
from uwlab.drivers.instruments.serial_light import SerialLight
from uwlab.drivers.instruments.visa_light import VisaLight, open_visa_light

__all__ = [
    "LightDefinition",
    "LightRig",
    "SerialLight",
    "SerialLightDefinition",
    "VisaLight",
    "load_any_light_definition",
    "load_light_definition",
    "load_light_rig",
    "open_light_instrument",
    "open_visa_light",
]
