"""Declarative vendor profiles: which GenICam feature backs each camera quantity, in what unit.

A profile is data, never code: for every interface quantity it lists the candidate device
features in order of preference (the first one the device exposes is used) with a linear
conversion ``interface_value = device_value * scale + offset`` or, for a device gain given as an amplitude
factor, its decibels ``interface_value = 20 log10(device_value * scale + offset)``. Feature names follow the GenICam
Standard Features Naming Convention (SFNC 2.x) unless a vendor's documented legacy names differ:

* FLIR Blackfly S (Spinnaker SFNC): ``ExposureTime`` [µs], ``Gain`` [dB], ``BlackLevel``,
  ``DeviceTemperature`` [°C], ``AcquisitionFrameRateEnable`` must be true to set a frame rate.
* Allied Vision GT / Prosilica (GigE legacy "Abs"/"Raw" names, AVT GigE features reference):
  ``ExposureTimeAbs`` [µs], ``Gain`` [dB] or ``GainRaw`` [dB on GT/GC models], ``BlackLevel``,
  ``AcquisitionFrameRateAbs`` [Hz], ``DeviceTemperature`` [°C], ``GevSCPSPacketSize``.
* Aravis fake camera (``src/arv-fake-camera.xml``, image from ``arv_fake_camera_diagonal_ramp`` in
  ``src/arvfakecamera.c``, Aravis 0.8): ``ExposureTimeAbs`` [µs], ``GainRaw`` (integer 0-10): the fake multiplies
  its ramp by ``1 + GainRaw + log10(t_exp / 10 ms)``, so at its default 10 ms exposure ``GainRaw`` = g is an
  amplitude gain of 1 + g, i.e. 20 log10(1 + g) dB (g = 1: 6.02 dB, g = 10: 20.8 dB);
  ``AcquisitionFrameRate`` [Hz]; no black level or temperature. Its ``BayerRG8`` and ``BayerBG8`` mosaics are
  each other's (red at (0, 0) in BayerBG8), a quirk its profile records in ``bayer_layouts``.
* Viky (the GenTL test producer in the ``genicam`` wheel): geometry, ``PixelFormat`` and
  ``AcquisitionFrameRate`` only.

A new camera model is a new `VendorProfile` entry in `PROFILES`; the generic SFNC profile is the
fallback when no vendor/model pattern matches.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from uwlab.drivers.camera.pixels import pixel_format


@dataclass(frozen=True)
class Feature:
    """A device feature and its linear conversion to the interface unit."""

    name: str
    scale: float = 1.0
    offset: float = 0.0
    decibel: bool = False

    def to_interface(self, device_value: float) -> float:
        linear = float(device_value) * self.scale + self.offset
        if not self.decibel:
            return linear
        return 20.0 * math.log10(linear) if linear > 0 else -math.inf

    def to_device(self, interface_value: float) -> float:
        linear = 10.0 ** (float(interface_value) / 20.0) if self.decibel else float(interface_value)
        return (linear - self.offset) / self.scale


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
    bayer_layouts: tuple[tuple[str, str], ...] = ()

    def bayer_layout(self, format_name: str) -> str | None:
        """The colour filter layout of ``format_name`` on this camera (``"RG"``: red at (0, 0), green at (0, 1)
        and (1, 0), blue at (1, 1), ...): the PFNC layout of the format unless the profile records that the
        device's mosaic differs; None for a monochrome format."""
        return dict(self.bayer_layouts).get(format_name, pixel_format(format_name).bayer)

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
        gain_db=(Feature("GainRaw", offset=1.0, decibel=True),),
        black_level=(),
        frame_rate_hz=(Feature("AcquisitionFrameRate"),),
        temperature_c=(),
        frame_rate_enable=(),
        auto_off=(("GainAuto", "Off"),),
        trigger_selector=(("TriggerSelector", "FrameStart"),),
        bayer_layouts=(("BayerRG8", "BG"), ("BayerBG8", "RG")),
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
