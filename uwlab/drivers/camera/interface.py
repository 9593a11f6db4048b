"""One camera interface over interchangeable transports (sim, harvesters/GenTL, Aravis).

Layering follows harvesters and ophyd-async: a backend only implements `Transport` — GenICam
feature access by name plus a raw buffer stream — and `Camera` does everything else the same
way for every backend: vendor-profile feature mapping (`profiles.py`), unit conversion, range
checks, auto modes off, ROI/binning, trigger modes, pixel unpacking (`pixels.py`), discarding
incomplete frames, bounded reconnects. The simulated camera therefore runs through exactly the
code path used with hardware.

Units: exposure in µs, gain in dB, frame rate in Hz, temperature in °C, black level in device
units (DN on most cameras), timestamps in ns of the device clock.
"""
from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import numpy as np

from uwlab.drivers.camera.pixels import pixel_format, unpack
from uwlab.drivers.camera.profiles import Feature, VendorProfile, select_profile
from uwlab.errors import ConfigError, DeviceError


class FrameTimeout(DeviceError):
    """No frame arrived within the acquisition timeout."""


class DeviceLost(DeviceError):
    """The device stopped answering (unplugged, powered off, server stopped)."""


@dataclass(frozen=True)
class RawFrame:
    """A buffer as delivered by a transport, before decoding. ``complete`` is False for frames
    with missing packets or a size mismatch; `Camera` discards those."""

    frame_id: int
    timestamp_ns: int
    width: int
    height: int
    pixel_format: str
    data: Any
    complete: bool = True


class Transport(Protocol):
    """What a backend provides: named GenICam features and a buffer stream."""

    backend: str
    device_id: str

    def has(self, name: str) -> bool: ...
    def get(self, name: str) -> Any: ...
    def set(self, name: str, value: Any) -> None: ...
    def bounds(self, name: str) -> tuple[float, float] | None: ...
    def entries(self, name: str) -> tuple[str, ...]: ...
    def execute(self, name: str) -> None: ...
    def start(self) -> None: ...
    def stop(self) -> None: ...
    def fetch(self, timeout_s: float) -> RawFrame: ...
    def reconnect(self) -> None: ...
    def close(self) -> None: ...


@dataclass(frozen=True)
class DeviceEntry:
    """One camera found by a backend's discovery."""

    backend: str
    id: str
    vendor: str
    model: str
    serial: str

    def to_dict(self) -> dict[str, str]:
        return asdict(self)


def unknown_device(backend: str, device_id: str, found: tuple[str, ...] | list[str]) -> DeviceError:
    """The error for a device id that discovery did not find, listing what was found."""
    listed = ", ".join(found) if found else "no device"
    return DeviceError(f"{backend}: unknown device id {device_id!r}; found: {listed}")


@dataclass(frozen=True)
class CameraInfo:
    backend: str
    device_id: str
    vendor: str
    model: str
    serial: str
    firmware: str
    sensor_width: int
    sensor_height: int
    profile: str


@dataclass(frozen=True)
class Settings:
    """Settings in force, read back from the device (None: the device has no such feature)."""

    exposure_us: float | None
    gain_db: float | None
    black_level: float | None
    pixel_format: str
    offset_x: int
    offset_y: int
    width: int
    height: int
    binning: tuple[int, int]
    frame_rate_hz: float | None
    trigger: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Frame:
    frame_id: int
    timestamp_ns: int
    image: np.ndarray
    pixel_format: str
    settings: Settings


@dataclass
class AcquisitionStats:
    """Counters over the camera's life: frames delivered, incomplete frames discarded,
    reconnects performed."""

    delivered: int = 0
    discarded: int = 0
    reconnects: int = 0


@dataclass(frozen=True)
class Policy:
    """Fault handling bounds: per-frame ``timeout_s``; at most ``max_discarded_in_row``
    consecutive incomplete frames; ``reconnect_attempts`` with exponential back-off from
    ``reconnect_delay_s``."""

    timeout_s: float = 2.0
    max_discarded_in_row: int = 20
    reconnect_attempts: int = 3
    reconnect_delay_s: float = 0.2


@dataclass
class _State:
    streaming: bool = False
    trigger: str = "free-run"
    in_force: Settings | None = None
    stats: AcquisitionStats = field(default_factory=AcquisitionStats)


class Camera:
    """A GenICam camera through any `Transport`. Use as a context manager: the device is
    always released, even when an exception escapes the block."""

    def __init__(self, transport: Transport, profile: VendorProfile | None = None, policy: Policy | None = None):
        self.transport = transport
        self.policy = policy or Policy()
        vendor, model = self._read_str("DeviceVendorName"), self._read_str("DeviceModelName")
        self.profile = profile or select_profile(vendor, model)
        self._state = _State()
        self.info = CameraInfo(
            backend=transport.backend,
            device_id=transport.device_id,
            vendor=vendor,
            model=model,
            serial=self._first_str(self.profile.serial),
            firmware=self._first_str(self.profile.firmware),
            sensor_width=int(self._get_or("SensorWidth", self._get_or("WidthMax", 0))),
            sensor_height=int(self._get_or("SensorHeight", self._get_or("HeightMax", 0))),
            profile=self.profile.name,
        )
        self.auto_off()

    # -- context management -------------------------------------------------------------
    def __enter__(self) -> Camera:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        try:
            self.stop()
        finally:
            self.transport.close()

    # -- feature helpers ------------------------------------------------------------------
    def _get_or(self, name: str, default: Any) -> Any:
        return self.transport.get(name) if self.transport.has(name) else default

    def _read_str(self, name: str) -> str:
        return str(self._get_or(name, "") or "").strip()

    def _first_str(self, names: tuple[str, ...]) -> str:
        return next((self._read_str(n) for n in names if self.transport.has(n)), "")

    def _feature(self, candidates: tuple[Feature, ...]) -> Feature | None:
        return next((f for f in candidates if self.transport.has(f.name)), None)

    def _read(self, candidates: tuple[Feature, ...]) -> float | None:
        feat = self._feature(candidates)
        return None if feat is None else feat.to_interface(self.transport.get(feat.name))

    def _write(self, key: str, candidates: tuple[Feature, ...], value: float) -> None:
        feat = self._feature(candidates)
        if feat is None:
            raise ConfigError(key, value, f"not supported by {self.info.vendor} {self.info.model}".strip())
        self._checked_set(key, feat, value)

    def _checked_set(self, key: str, feat: Feature, value: float) -> None:
        bounds = self.transport.bounds(feat.name)
        device_value = feat.to_device(value)
        if bounds is not None and not bounds[0] - 1e-9 <= device_value <= bounds[1] + 1e-9:
            lo, hi = sorted((feat.to_interface(bounds[0]), feat.to_interface(bounds[1])))
            raise ConfigError(key, value, f"out of range for {feat.name}: allowed [{lo:g}, {hi:g}]")
        current = self.transport.get(feat.name)
        if isinstance(current, int) and not isinstance(current, bool):
            device_value = int(round(device_value))
        self.transport.set(feat.name, device_value)
        self._refresh()

    def _set_int(self, key: str, name: str, value: int) -> None:
        if not self.transport.has(name):
            if value in (0, 1):
                return
            raise ConfigError(key, value, f"device has no {name} feature")
        self._checked_set(key, Feature(name), int(value))

    def _set_optional(self, name: str, value: object) -> None:
        if self.transport.has(name) and value in self._allowed(name, value):
            self.transport.set(name, value)

    def _allowed(self, name: str, value: object) -> tuple:
        entries = self.transport.entries(name)
        return entries if entries else (value,)

    def _refresh(self) -> None:
        if self._state.streaming:
            self._state.in_force = self.read_settings()

    # -- settings ---------------------------------------------------------------------------
    def auto_off(self) -> None:
        """Switch automatic exposure, gain and black level off (before any measurement)."""
        for name, value in self.profile.auto_off:
            self._set_optional(name, value)

    @property
    def exposure_us(self) -> float | None:
        return self._read(self.profile.exposure_us)

    @exposure_us.setter
    def exposure_us(self, value: float) -> None:
        self._write("exposure_us", self.profile.exposure_us, value)

    @property
    def gain_db(self) -> float | None:
        return self._read(self.profile.gain_db)

    @gain_db.setter
    def gain_db(self, value: float) -> None:
        self._write("gain_db", self.profile.gain_db, value)

    @property
    def black_level(self) -> float | None:
        return self._read(self.profile.black_level)

    @black_level.setter
    def black_level(self, value: float) -> None:
        self._write("black_level", self.profile.black_level, value)

    @property
    def frame_rate_hz(self) -> float | None:
        return self._read(self.profile.frame_rate_hz)

    @frame_rate_hz.setter
    def frame_rate_hz(self, value: float) -> None:
        for name, enable in self.profile.frame_rate_enable:
            self._set_optional(name, enable)
        self._write("frame_rate_hz", self.profile.frame_rate_hz, value)

    @property
    def temperature_c(self) -> float | None:
        return self._read(self.profile.temperature_c)

    @property
    def pixel_formats(self) -> tuple[str, ...]:
        return self.transport.entries("PixelFormat")

    @property
    def pixel_format(self) -> str:
        return str(self.transport.get("PixelFormat"))

    @pixel_format.setter
    def pixel_format(self, name: str) -> None:
        pixel_format(name)
        if name not in self.pixel_formats:
            raise ConfigError("pixel_format", name, f"not offered by the device; offered: {', '.join(self.pixel_formats)}")
        self.transport.set("PixelFormat", name)
        self._refresh()

    def set_roi(self, x: int, y: int, width: int, height: int) -> None:
        """Region of interest in (binned) pixels; offsets are zeroed first so that every
        intermediate state is valid on the device."""
        for name in ("OffsetX", "OffsetY"):
            if self.transport.has(name):
                self.transport.set(name, 0)
        self._set_int("roi.width", "Width", width)
        self._set_int("roi.height", "Height", height)
        self._set_int("roi.x", "OffsetX", x)
        self._set_int("roi.y", "OffsetY", y)

    def set_binning(self, horizontal: int, vertical: int) -> None:
        self._set_int("binning.horizontal", "BinningHorizontal", horizontal)
        self._set_int("binning.vertical", "BinningVertical", vertical)

    def set_trigger(self, mode: str) -> None:
        """``"free-run"`` or ``"software"`` (frame start on `trigger`)."""
        if mode not in ("free-run", "software"):
            raise ConfigError("trigger", mode, "expected 'free-run' or 'software'")
        for name, value in self.profile.trigger_selector:
            self._set_optional(name, value)
        if mode == "software":
            if not self.transport.has("TriggerSoftware"):
                raise ConfigError("trigger", mode, "device has no TriggerSoftware feature")
            self.transport.set("TriggerSource", "Software")
        if self.transport.has("TriggerMode"):
            self.transport.set("TriggerMode", "On" if mode == "software" else "Off")
        self._state.trigger = mode
        self._refresh()

    def trigger(self) -> None:
        self.transport.execute("TriggerSoftware")

    def read_settings(self) -> Settings:
        """Every setting read back from the device now."""
        return Settings(
            exposure_us=self.exposure_us,
            gain_db=self.gain_db,
            black_level=self.black_level,
            pixel_format=self.pixel_format,
            offset_x=int(self._get_or("OffsetX", 0)),
            offset_y=int(self._get_or("OffsetY", 0)),
            width=int(self.transport.get("Width")),
            height=int(self.transport.get("Height")),
            binning=(int(self._get_or("BinningHorizontal", 1)), int(self._get_or("BinningVertical", 1))),
            frame_rate_hz=self.frame_rate_hz,
            trigger=self._state.trigger,
        )

    # -- acquisition --------------------------------------------------------------------------
    @property
    def stats(self) -> AcquisitionStats:
        return self._state.stats

    def start(self) -> None:
        if not self._state.streaming:
            self._state.in_force = self.read_settings()
            self.transport.start()
            self._state.streaming = True

    def stop(self) -> None:
        if self._state.streaming:
            self._state.streaming = False
            self.transport.stop()

    def acquire(self, n: int) -> list[Frame]:
        """Acquire ``n`` complete frames (starting and stopping the stream if it was idle)."""
        return list(self.frames(n))

    def frames(self, n: int) -> Iterator[Frame]:
        """``n`` complete frames, one at a time (memory of one frame), starting and stopping the stream if it was
        idle."""
        was_streaming = self._state.streaming
        try:
            yield from self.stream(n)
        finally:
            if not was_streaming:
                self.stop()

    def stream(self, n: int | None = None) -> Iterator[Frame]:
        """Yield complete frames (forever when ``n`` is None) while the stream runs."""
        self.start()
        count = 0
        while n is None or count < n:
            yield self._next_frame()
            count += 1

    def _next_frame(self) -> Frame:
        in_row = 0
        while True:
            raw = self._fetch_one()
            if raw is None:
                continue
            if raw.complete:
                self._state.stats.delivered += 1
                return self._decode(raw)
            self._state.stats.discarded += 1
            in_row += 1
            if in_row > self.policy.max_discarded_in_row:
                raise DeviceError(f"{self.info.device_id}: {in_row} incomplete frames in a row")

    def _fetch_one(self) -> RawFrame | None:
        """One buffer, or None when the device had to be reconnected."""
        if self._state.trigger == "software":
            self.trigger()
        try:
            return self.transport.fetch(self.policy.timeout_s)
        except FrameTimeout as exc:
            raise DeviceError(f"{self.info.device_id}: acquisition timeout ({self.policy.timeout_s * 1e3:.0f} ms): {exc}") from exc
        except DeviceLost:
            self._reconnect()
            return None

    def _decode(self, raw: RawFrame) -> Frame:
        fmt = pixel_format(raw.pixel_format)
        image = unpack(raw.data, fmt, raw.width, raw.height)
        return Frame(raw.frame_id, raw.timestamp_ns, image, fmt.name, self._state.in_force)

    def _reconnect(self) -> None:
        wanted = self._state.in_force
        last: Exception | None = None
        for attempt in range(self.policy.reconnect_attempts):
            time.sleep(self.policy.reconnect_delay_s * 2**attempt)
            try:
                self.transport.reconnect()
                self._restore(wanted)
                self._state.stats.reconnects += 1
                return
            except DeviceError as exc:
                last = exc
        self._state.streaming = False
        raise DeviceError(
            f"{self.info.device_id}: device lost mid-stream; {self.policy.reconnect_attempts} reconnect attempts failed ({last})"
        )

    def _restore(self, wanted: Settings) -> None:
        self._state.streaming = False
        self.auto_off()
        self.pixel_format = wanted.pixel_format
        if self.transport.has("BinningHorizontal"):
            self.set_binning(*wanted.binning)
        self.set_roi(wanted.offset_x, wanted.offset_y, wanted.width, wanted.height)
        for key, value in (("exposure_us", wanted.exposure_us), ("gain_db", wanted.gain_db), ("black_level", wanted.black_level)):
            if value is not None:
                setattr(self, key, value)
        self.set_trigger(wanted.trigger)
        self.start()
