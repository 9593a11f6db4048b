"""Lab instruments declared in files: a light (LED driver, programmable DC supply) over VISA through PyVISA.

An instrument definition (``configs/instruments/NAME.toml``, `definition`) names the adapter, the command strings,
the limits and how a light level in [0, 1] maps to the drive; `VisaLight` drives any such instrument through a
PyVISA resource (the pure-Python ``@py`` backend by default; a vendor VISA or ``PATH.yaml@sim``, pyvisa-sim, with
``visa_library``). A new instrument of a known family is a new definition file, no Python (docs/instruments.md).
"""

from __future__ import annotations

from uwlab.drivers.instruments.definition import LightDefinition, load_light_definition
from uwlab.drivers.instruments.visa_light import VisaLight, open_visa_light

__all__ = ["LightDefinition", "VisaLight", "load_light_definition", "open_visa_light"]
