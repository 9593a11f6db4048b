"""Declarative vendor profiles: which GenICam feature backs each camera quantity, in what unit.

A profile is data, never code: for every interface quantity it lists the candidate device
features in order of preference (the first one the device exposes is used) with a linear
conversion ``interface_value = device_value * scale + offset``. Feature names follow the GenICam
Standard Features Naming Convention (SFNC 2.x) unless a vendor's documented legacy names differ:

* FLIR Blackfly S (Spinnaker SFNC): ``ExposureTime`` [µs], ``Gain`` [dB], ``BlackLevel``,
  ``DeviceTemperature`` [°C], ``AcquisitionFrameRateEnable`` must be true to set a frame rate.
* Allied Vision GT / Prosilica (GigE legacy "Abs"/"Raw" names, AVT GigE features reference):
  ``ExposureTimeAbs`` [µs], ``Gain`` [dB] or ``GainRaw`` [dB on GT/GC models], ``BlackLevel``,
  ``AcquisitionFrameRateAbs`` [Hz], ``DeviceTemperature`` [°C], ``GevSCPSPacketSize``.
* Aravis fake camera (``src/arv-fake-camera.xml``): ``ExposureTimeAbs`` [µs], ``GainRaw``
  (unitless 0-10, taken as dB), ``AcquisitionFrameRate``; no black level or temperature.
* Viky (the GenTL test producer in the ``genicam`` wheel): geometry, ``PixelFormat`` and
  ``AcquisitionFrameRate`` only.

A new camera model is a new `VendorProfile` entry in `PROFILES`; the generic SFNC profile is the
fallback when no vendor/model pattern matches.
"""

from __future__ import annotations

import re
from dataclasses import dataclass


@dataclass(frozen=True)
class Feature:
    """A device feature and its linear conversion to the interface unit."""

    name: str
    scale: float = 1.0
    offset: float = 0.0

    def to_interface(self, device_value: float) -> float:
        return float(device_value) * self.scale + self.offset

    def to_device(self, interface_value: float) -> float:
        return (float(interface_value) - self.offset) / self.scale


SFNC_EXPOSURE = (Feature("ExposureTime"), Feature("ExposureTimeAbs"))
SFNC_GAIN = (Feature("Gain"),)
SFNC_BLACK = (Feature("BlackLevel"),)
SFNC_RATE = (Feature("AcquisitionFrameRate"), Feature("AcquisitionFrameRateAbs"))
SFNC_TEMPERATURE = (Feature("DeviceTemperature"),)
SFNC_AUTO_OFF = (("ExposureAuto", "Off"), ("GainAuto", "Off"), ("BlackLevelAuto", "Off"))


@dataclass(frozen=True)
class VendorProfile:
    """Feature names and units of one family of cameras, matched on vendor and model names
    (case-insensitive regular expressions, ``re.search``)."""

    name: str
    vendor: str = ".*"
    model: str = ".*"
    exposure_us: tuple[Feature, ...] = SFNC_EXPOSURE
    gain_db: tuple[Feature, ...] = SFNC_GAIN
    black_level: tuple[Feature, ...] = SFNC_BLACK
    frame_rate_hz: tuple[Feature, ...] = SFNC_RATE
    temperature_c: tuple[Feature, ...] = SFNC_TEMPERATURE
    frame_rate_enable: tuple[tuple[str, object], ...] = (("AcquisitionFrameRateEnable", True),)
    auto_off: tuple[tuple[str, object], ...] = SFNC_AUTO_OFF
    trigger_selector: tuple[tuple[str, object], ...] = (("TriggerSelector", "FrameStart"),)
    packet_size: str | None = "GevSCPSPacketSize"
    firmware: tuple[str, ...] = ("DeviceFirmwareVersion", "DeviceVersion")
    serial: tuple[str, ...] = ("DeviceSerialNumber", "DeviceID")

    def matches(self, vendor: str, model: str) -> bool:
        return bool(re.search(self.vendor, vendor or "", re.I) and re.search(self.model, model or "", re.I))


GENERIC_SFNC = VendorProfile("generic-sfnc")

PROFILES: tuple[VendorProfile, ...] = (
    VendorProfile(
        "flir-blackfly-s",
        vendor=r"FLIR|Point ?Grey",
        model=r"Blackfly S|^BFS",
        exposure_us=(Feature("ExposureTime"),),
        gain_db=(Feature("Gain"),),
        frame_rate_hz=(Feature("AcquisitionFrameRate"),),
        auto_off=(("ExposureAuto", "Off"), ("GainAuto", "Off")),
    ),
    VendorProfile(
        "allied-vision-gt",
        vendor=r"Allied ?Vision|^AVT|Prosilica",
        model=r"^GT|Prosilica GT|^GC|^GX",
        exposure_us=(Feature("ExposureTimeAbs"), Feature("ExposureTime")),
        gain_db=(Feature("Gain"), Feature("GainRaw")),
        frame_rate_hz=(Feature("AcquisitionFrameRateAbs"), Feature("AcquisitionFrameRate")),
        frame_rate_enable=(),
        auto_off=(("ExposureAuto", "Off"), ("GainAuto", "Off")),
    ),
    VendorProfile(
        "aravis-fake",
        vendor=r"^Aravis$",
        model=r"Fake",
        exposure_us=(Feature("ExposureTimeAbs"),),
        gain_db=(Feature("GainRaw"),),
        black_level=(),
        frame_rate_hz=(Feature("AcquisitionFrameRate"),),
        temperature_c=(),
        frame_rate_enable=(),
        auto_off=(("GainAuto", "Off"),),
        trigger_selector=(("TriggerSelector", "FrameStart"),),
    ),
    VendorProfile(
        "viky",
        vendor=r"Machine Vision Games",
        model=r"Viky",
        exposure_us=(),
        gain_db=(),
        black_level=(),
        frame_rate_hz=(Feature("AcquisitionFrameRate"),),
        temperature_c=(),
        frame_rate_enable=(),
        auto_off=(),
        trigger_selector=(),
        packet_size=None,
    ),
)


def select_profile(vendor: str, model: str, profiles: tuple[VendorProfile, ...] = PROFILES) -> VendorProfile:
    """The first profile whose vendor and model patterns match, else the generic SFNC profile."""
    return next((p for p in profiles if p.matches(vendor, model)), GENERIC_SFNC)
