"""The simulated Ocean Insight spectrometer (`uwlab.sim.devices.ocean_insight`) as the tests use it, and the check
that it still has python-seabreeze's API.

`fake_seabreeze(*devices)` is seabreeze's own ``Spectrometer`` class finding the simulated ``devices``
(`uwlab.sim.devices.ocean_insight.spectrometer_class`). `api_mismatches()` compares every public member of the
simulated backend device and its features with seabreeze's declarations (``seabreeze.types``) and the spectrometer
class with seabreeze's by `inspect.signature`: a renamed method or parameter in a new seabreeze release fails the
tests that use the simulation.

The lamp truth: a blackbody at 3100 K of known absolute irradiance (`lamp_w_m2_nm`); the calibration file
``tests/data/ocean_insight_calibration_3100k.csv`` tabulates `calibration_uj_per_count` (the simulated instrument's
response) on 335–1065 nm in 1 nm steps.
"""

from __future__ import annotations

import inspect

import numpy as np
from seabreeze.spectrometers import Spectrometer as SeabreezeSpectrometer
from seabreeze.types import SeaBreezeDevice as SeabreezeDeviceProtocol
from seabreeze.types import SeaBreezeNonlinearityCoefficientsFeature, SeaBreezeSpectrometerFeature

from uwlab.sim.devices.ocean_insight import (
    CC3_AREA_CM2,
    NonlinearityFeature,
    SimBench,
    SimSeaBreezeDevice,
    SimulatedDevice,
    SpectrometerFeature,
    lamp_w_m2_nm,
    neighbour_spread_nm,
    spectrometer_class,
)
from uwlab.sim.devices.ocean_insight import response_uj_per_count as calibration_uj_per_count

__all__ = [
    "CC3_AREA_CM2",
    "SimulatedDevice",
    "api_mismatches",
    "calibration_uj_per_count",
    "fake_seabreeze",
    "lamp_counts_per_s",
    "lamp_w_m2_nm",
    "neighbour_spread_nm",
    "optical",
]


def fake_seabreeze(*devices: SimulatedDevice) -> type[SeabreezeSpectrometer]:
    """seabreeze's ``Spectrometer`` class with ``devices`` attached (what it would find on the USB bus)."""
    return spectrometer_class(*devices)


def _public(cls) -> dict[str, object]:
    return {
        name: inspect.getattr_static(cls, name) for name in dir(cls) if not name.startswith("_") and name != "attached"
    }


def _signature(member) -> list[tuple]:
    function = member.__func__ if isinstance(member, (classmethod, staticmethod)) else member
    return [(p.name, p.kind, p.default) for p in inspect.signature(function).parameters.values()]


def _mismatches(fake, real, label: str) -> list[str]:
    problems = []
    for name, member in _public(fake).items():
        if not hasattr(real, name) and name not in getattr(real, "__annotations__", {}):
            problems.append(f"{label}.{name}: not in seabreeze")
            continue
        if not hasattr(real, name):
            continue  # a declared attribute (``serial_number: str``), served here by a property
        original = inspect.getattr_static(real, name)
        if isinstance(member, property) != isinstance(original, property) or isinstance(
            member, classmethod
        ) != isinstance(original, classmethod):
            problems.append(f"{label}.{name}: {type(member).__name__} here, {type(original).__name__} in seabreeze")
        elif callable(member) or isinstance(member, classmethod):
            if _signature(member) != _signature(original):
                problems.append(
                    f"{label}.{name}{inspect.signature(member)}: seabreeze has {inspect.signature(original)}"
                )
    return problems


def api_mismatches() -> list[str]:
    """Where the simulation's API differs from seabreeze's (empty: it matches)."""
    from seabreeze.types import SeaBreezeFeatureAccessor

    accessor = SeaBreezeFeatureAccessor.__annotations__
    features = vars(SimSeaBreezeDevice(SimulatedDevice()).f)
    return (
        _mismatches(fake_seabreeze(), SeabreezeSpectrometer, "Spectrometer")
        + _mismatches(SimSeaBreezeDevice, SeabreezeDeviceProtocol, "SeaBreezeDevice")
        + _mismatches(SpectrometerFeature, SeaBreezeSpectrometerFeature, "f.spectrometer")
        + _mismatches(NonlinearityFeature, SeaBreezeNonlinearityCoefficientsFeature, "f.nonlinearity_coefficients")
        + [f"f.{name}: not a seabreeze feature" for name in features if name not in accessor]
    )


def lamp_counts_per_s(device: SimulatedDevice, area_cm2: float = CC3_AREA_CM2) -> np.ndarray:
    """Counts per second the default lamp gives each pixel of ``device`` behind an optic of ``area_cm2`` (the
    simulated bench's: E · A · dλ / C)."""
    saved = device.signal_counts_per_s
    counts = SimBench(device=device, area_cm2=area_cm2).device.signal_counts_per_s
    device.signal_counts_per_s = saved
    assert counts is not None
    return counts


def optical(device: SimulatedDevice) -> np.ndarray:
    """The pixels that see light (not the masked electric-dark ones)."""
    mask = np.ones(device.wavelength_nm.size, dtype=bool)
    mask[device.dark_pixel_indices] = False
    return mask
