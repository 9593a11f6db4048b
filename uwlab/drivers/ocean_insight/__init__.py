"""Ocean Insight (Ocean Optics) spectrometers through python-seabreeze, with OceanView's absolute-irradiance
calibration (`radiometry`), Ocean's own files (`files`: ``*_OOIIrrad.cal``, ``.LMP``, OceanView exports),
instrument definitions (`definition`) and the driver (`device`); docs/spectrometers.md.
"""

from __future__ import annotations

from uwlab.drivers.ocean_insight.definition import OceanInsightDefinition, load_definition
from uwlab.drivers.ocean_insight.device import (
    DarkSpectrum,
    OceanInsightSpectrometer,
    open_instrument,
    open_ocean_insight,
    read_dark,
    write_dark,
)
from uwlab.drivers.ocean_insight.files import read_lamp, read_ocean_calibration, read_oceanview_spectrum
from uwlab.drivers.ocean_insight.radiometry import read_calibration

__all__ = [
    "DarkSpectrum",
    "OceanInsightDefinition",
    "OceanInsightSpectrometer",
    "load_definition",
    "open_instrument",
    "open_ocean_insight",
    "read_calibration",
    "read_lamp",
    "read_ocean_calibration",
    "read_oceanview_spectrum",
    "read_dark",
    "write_dark",
]
