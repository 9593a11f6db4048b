"""One camera interface over interchangeable transports (sim, harvesters/GenTL, Aravis).

Layering follows harvesters and ophyd-async: a backend only implements `Transport` — GenICam
feature access by name plus a raw buffer stream — and `Camera` does everything else the same
way for every backend: vendor-profile feature mapping (`profiles.py`), unit conversion, range
checks, auto modes off, ROI/binning, trigger modes, pixel unpacking (`pixels.py`), discarding
incomplete frames, bounded reconnects. The simulated camera therefore runs through exactly the
code path used with hardware.

Outages: every public operation (a setting read or written, acquisition start, trigger, frame
fetch, ``acquire``) survives the device going away. A backend reports a vanished device with
`DeviceLost`; the operation then reconnects with exponential back-off within the bounds of its
`Policy`, re-applies the settings in force before the loss (`Camera.settings_in_force`), reads
every one back and compares, restarts acquisition if it was running, and runs again from its
start (so ``acquire(n)`` returns n frames from one connection). Past the bounds: one
`DeviceError`. `AcquisitionStats.reconnects` counts the recoveries, so a caller can tell that one
happened during a measurement.

Units: exposure in µs, gain in dB, frame rate in Hz, temperature in °C, black level in device
units (DN on most cameras), timestamps in ns of the device clock.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Protocol, TypeVar

import numpy as np

from uwlab.drivers.camera.pixels import pixel_format, unpack
from uwlab.drivers.camera.profiles import Feature, VendorProfile, select_profile
from uwlab.errors import ConfigError, DeviceError


class FrameTimeout(DeviceError):
    """No frame arrived within the acquisition timeout."""


class DeviceLost(DeviceError):
    """The device stopped answering or its control channel was taken away (unplugged, powered
    off, restarted, server stopped or frozen): `Camera` reconnects."""


@dataclass(frozen=True)
class RawFrame:
    """A buffer as delivered by a transport, before decoding. ``problem`` is what made it incomplete (missing
    packets, a size mismatch, as the transport reports it; empty for a complete frame); `Camera` discards those."""

    frame_id: int
    timestamp_ns: int
    width: int
    height: int
    pixel_format: str
    data: Any
    problem: str = ""

    @property
    def complete(self) -> bool:
        return not self.problem


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

    def disagreements(self, other: Settings, rel_tol: float = 1e-9) -> list[str]:
        """``name: self -> other`` for every setting that differs (floats to ``rel_tol``)."""
        out = []
        for f in fields(self):
            mine, theirs = getattr(self, f.name), getattr(other, f.name)
            if isinstance(mine, float) and isinstance(theirs, float):
                same = math.isclose(mine, theirs, rel_tol=rel_tol, abs_tol=1e-12)
            else:
                same = mine == theirs
            if not same:
                out.append(f"{f.name}: {mine!r} -> {theirs!r}")
        return out


@dataclass(frozen=True)
class Frame:
    """A decoded frame. ``bayer``: the colour filter layout of a raw colour image (``"RG"``, ``"GR"``, ``"GB"``,
    ``"BG"``: the filters of the first row's first two pixels, `uwlab.drivers.camera.pixels.bayer_sites`) as this
    camera delivers it (its profile may correct the format's name); None for a monochrome image."""

    frame_id: int
    timestamp_ns: int
    image: np.ndarray
    pixel_format: str
    settings: Settings
    bayer: str | None = None


@dataclass
class AcquisitionStats:
    """Counters over the camera's life: frames delivered, incomplete frames discarded,
    reconnects performed."""

    delivered: int = 0
    discarded: int = 0
    reconnects: int = 0


# The longest any wait of a camera may be: a day (beyond it a value is a unit error; 1e308 s would overflow the
# backends' integer microseconds)
MAX_WAIT_S = 86_400


@dataclass(frozen=True)
class Policy:
    """Fault handling bounds.

    ``timeout_s``: per frame (then "acquisition timeout"); ``max_discarded_in_row``: consecutive
    incomplete frames. A lost device is reconnected; attempt k (from 0) waits
    ``min(reconnect_delay_s · 2**k, reconnect_max_delay_s)`` first, and the camera gives up when
    ``reconnect_attempts`` attempts have failed or ``outage_limit_s`` have passed since the loss
    was noticed, whichever comes first. The defaults ride out a 10 s outage (about 8 attempts).
    """

    timeout_s: float = 2.0
    max_discarded_in_row: int = 20
    reconnect_attempts: int = 12
    reconnect_delay_s: float = 0.2
    reconnect_max_delay_s: float = 2.0
    outage_limit_s: float = 30.0

    def __post_init__(self) -> None:
        for name in ("timeout_s", "reconnect_delay_s", "reconnect_max_delay_s", "outage_limit_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0 < value <= MAX_WAIT_S):
                raise ConfigError(f"policy.{name}", value, f"must be a number of seconds in (0, {MAX_WAIT_S}]")
        for name in ("max_discarded_in_row", "reconnect_attempts"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ConfigError(f"policy.{name}", value, "must be an integer >= 0")

    def backoff_s(self, attempt: int) -> float:
        """The wait before reconnect attempt ``attempt`` (0, 1, ...)."""
        return min(self.reconnect_delay_s * 2.0 ** min(attempt, 60), self.reconnect_max_delay_s)


@dataclass
class _State:
    streaming: bool = False
    trigger: str = "free-run"
    frame_rate_set: bool = False
    in_force: Settings | None = None
    operation_depth: int = 0
    stats: AcquisitionStats = field(default_factory=AcquisitionStats)


F = TypeVar("F", bound=Callable[..., Any])


@dataclass
class _Outage:
    """One operation's outage: when the loss was first noticed and the reconnect attempts spent on it (a device
    lost again right after a successful reconnect continues the same outage, within the same limits)."""

    noticed: float
    attempts: int = 0


def _survives_outages(method: F) -> F:
    """Run a public operation; if the device is lost, reconnect (`Camera._reconnect`) and run it
    again from its start. Only the outermost operation does this: nested ones let `DeviceLost` pass."""

    @functools.wraps(method)
    def operation(self: Camera, *args: Any, **kwargs: Any) -> Any:
        state = self._state
        if state.operation_depth:
            return method(self, *args, **kwargs)
        state.operation_depth += 1
        outage: _Outage | None = None
        try:
            while True:
                try:
                    return method(self, *args, **kwargs)
                except DeviceLost as lost:
                    outage = outage or _Outage(time.monotonic())
                    self._reconnect(lost, outage)
        finally:
            state.operation_depth -= 1

    return operation  # type: ignore[return-value]


class Camera:
    """A GenICam camera through any `Transport`. Use as a context manager: the device is
    always released, even when an exception escapes the block."""

    def __init__(self, transport: Transport, profile: VendorProfile | None = None, policy: Policy | None = None):
        self.transport = transport
        self.policy = policy or Policy()
        self._state = _State()
        vendor, model = self._read_str("DeviceVendorName"), self._read_str("DeviceModelName")
        self.profile = profile or select_profile(vendor, model)
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
        self._state.in_force = self.read_settings()

    # -- settings ---------------------------------------------------------------------------
    @_survives_outages
    def auto_off(self) -> None:
        """Switch automatic exposure, gain and black level off (before any measurement)."""
        for name, value in self.profile.auto_off:
            self._set_optional(name, value)
        self._refresh()

    def _auto_modes_left_on(self) -> list[str]:
        return [
            f"{name}: {self.transport.get(name)!r} (want {value!r})"
            for name, value in self.profile.auto_off
            if self.transport.has(name) and value in self._allowed(name, value) and self.transport.get(name) != value
        ]

    @property
    @_survives_outages
    def exposure_us(self) -> float | None:
        return self._read(self.profile.exposure_us)

    @exposure_us.setter
    @_survives_outages
    def exposure_us(self, value: float) -> None:
        self._write("exposure_us", self.profile.exposure_us, value)

    @property
    @_survives_outages
    def gain_db(self) -> float | None:
        return self._read(self.profile.gain_db)

    @gain_db.setter
    @_survives_outages
    def gain_db(self, value: float) -> None:
        self._write("gain_db", self.profile.gain_db, value)

    @property
    @_survives_outages
    def black_level(self) -> float | None:
        return self._read(self.profile.black_level)

    @black_level.setter
    @_survives_outages
    def black_level(self, value: float) -> None:
        self._write("black_level", self.profile.black_level, value)

    @property
    @_survives_outages
    def frame_rate_hz(self) -> float | None:
        return self._read(self.profile.frame_rate_hz)

    @frame_rate_hz.setter
    @_survives_outages
    def frame_rate_hz(self, value: float) -> None:
        for name, enable in self.profile.frame_rate_enable:
            self._set_optional(name, enable)
        self._write("frame_rate_hz", self.profile.frame_rate_hz, value)
        self._state.frame_rate_set = True

    @property
    @_survives_outages
    def temperature_c(self) -> float | None:
        return self._read(self.profile.temperature_c)

    @property
    @_survives_outages
    def pixel_formats(self) -> tuple[str, ...]:
        return self.transport.entries("PixelFormat")

    @property
    @_survives_outages
    def pixel_format(self) -> str:
        return str(self.transport.get("PixelFormat"))

    @pixel_format.setter
    @_survives_outages
    def pixel_format(self, name: str) -> None:
        pixel_format(name)
        if name not in self.pixel_formats:
            raise ConfigError(
                "pixel_format", name, f"not offered by the device; offered: {', '.join(self.pixel_formats)}"
            )
        self.transport.set("PixelFormat", name)
        self._refresh()

    @property
    def bayer_layout(self) -> str | None:
        """The colour filter layout of the current pixel format on this camera (None: monochrome)."""
        return self.profile.bayer_layout(self.pixel_format)

    def bayer_format(self, layout: str) -> str | None:
        """The pixel format delivering the colour filter ``layout`` on this device, as its profile reads the mosaic
        (Aravis's fake camera delivers RG in its BayerBG8): the current format if it does, else an offered one of
        the current format's bit depth, else the first offered that does; None when none does."""

        def delivers(name: str) -> bool:
            try:
                return self.profile.bayer_layout(name) == layout
            except ConfigError:  # a format uwlab does not read (RGB8, ...)
                return False

        current = self.pixel_format
        if delivers(current):
            return current
        offered = [name for name in self.pixel_formats if delivers(name)]
        try:
            bits = pixel_format(current).bits
        except ConfigError:
            bits = None
        same_depth = [name for name in offered if pixel_format(name).bits == bits]
        return next(iter(same_depth or offered), None)

    def check_bayer(self, layout: str) -> None:
        """Refuse (`ConfigError`) when the device's pixel format does not deliver the colour filter ``layout``
        the caller expects (e.g. a colour sensor profile's or the operator's)."""
        if layout != self.bayer_layout:
            pf = self.pixel_format
            raise ConfigError(
                "bayer",
                layout,
                f"the device's PixelFormat {pf} is "
                f"{f'Bayer {self.bayer_layout}' if self.bayer_layout else 'monochrome'}"
                f" on {self.info.vendor} {self.info.model}".rstrip(),
            )

    @_survives_outages
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

    @_survives_outages
    def set_binning(self, horizontal: int, vertical: int) -> None:
        self._set_int("binning.horizontal", "BinningHorizontal", horizontal)
        self._set_int("binning.vertical", "BinningVertical", vertical)

    @_survives_outages
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

    @_survives_outages
    def trigger(self) -> None:
        self.transport.execute("TriggerSoftware")

    @_survives_outages
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
            trigger=self._read_trigger(),
        )

    def _read_trigger(self) -> str:
        if self.transport.has("TriggerMode"):
            return "software" if self.transport.get("TriggerMode") == "On" else "free-run"
        return self._state.trigger

    @property
    def settings_in_force(self) -> Settings:
        """The settings read back after the last change (what a reconnect restores); read on opening."""
        if self._state.in_force is None:
            raise DeviceError(f"{self.info.device_id}: settings not read back yet")
        return self._state.in_force

    @_survives_outages
    def verify_settings(self) -> Settings:
        """Read every setting back and compare it with `settings_in_force`. A device whose settings changed
        behind our back (it rebooted without our noticing, e.g. a GigE camera restarted between two reads) is
        treated as lost: reconnected, its settings restored and verified (`stats.reconnects` counts it)."""
        now = self.read_settings()
        changed = self.settings_in_force.disagreements(now)
        if changed:
            raise DeviceLost(f"{self.info.device_id}: settings changed behind our back ({'; '.join(changed)})")
        return now

    # -- acquisition --------------------------------------------------------------------------
    @property
    def stats(self) -> AcquisitionStats:
        return self._state.stats

    @_survives_outages
    def start(self) -> None:
        if not self._state.streaming:
            self._state.in_force = self.read_settings()
            self.transport.start()
            self._state.streaming = True

    def stop(self) -> None:
        """Stop acquiring. A lost device is not acquiring either, and a reconnect leaves it stopped."""
        if self._state.streaming:
            self._state.streaming = False
            try:
                self.transport.stop()
            except DeviceLost:
                pass

    def acquire(self, n: int) -> list[Frame]:
        """Acquire ``n`` complete frames (starting and stopping the stream if it was idle). After a
        reconnect the acquisition starts over, so all ``n`` frames come from one connection."""
        was_streaming = self._state.streaming
        try:
            return self._acquire(n)
        finally:
            if not was_streaming:
                self.stop()

    def frames(self, n: int) -> Iterator[Frame]:
        """``n`` complete frames, one at a time (memory of one frame), starting and stopping the stream if it was
        idle. A reconnect in between resumes the stream (`stats.reconnects` tells the caller)."""
        was_streaming = self._state.streaming
        try:
            yield from self.stream(n)
        finally:
            if not was_streaming:
                self.stop()

    @_survives_outages
    def _acquire(self, n: int) -> list[Frame]:
        self.start()
        return [self._next_frame() for _ in range(n)]

    def stream(self, n: int | None = None) -> Iterator[Frame]:
        """Yield complete frames (forever when ``n`` is None) while the stream runs."""
        self.start()
        count = 0
        while n is None or count < n:
            yield self._next_frame()
            count += 1

    @_survives_outages
    def _next_frame(self) -> Frame:
        """The next complete frame within ``policy.timeout_s`` (incomplete ones discarded meanwhile)."""
        deadline = time.monotonic() + self.policy.timeout_s
        in_row = 0
        while True:
            raw = self._fetch_one(deadline, in_row)
            if raw.complete:
                self._state.stats.delivered += 1
                return self._decode(raw)
            self._state.stats.discarded += 1
            in_row += 1
            if in_row > self.policy.max_discarded_in_row:
                raise DeviceError(
                    f"{self.info.device_id}: {in_row} incomplete frames in a row (the last: {raw.problem})"
                )

    def _fetch_one(self, deadline: float, discarded: int) -> RawFrame:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise DeviceError(f"{self._timeout_message(discarded)}: no complete frame")
        if self._state.trigger == "software":
            self.transport.execute("TriggerSoftware")
        try:
            return self.transport.fetch(remaining)
        except FrameTimeout as exc:
            raise DeviceError(f"{self._timeout_message(discarded)}: {exc}") from exc

    def _timeout_message(self, discarded: int) -> str:
        timeout = f"{self.info.device_id}: acquisition timeout ({self.policy.timeout_s * 1e3:.0f} ms"
        return timeout + (f", {discarded} incomplete frames discarded)" if discarded else ")")

    def _decode(self, raw: RawFrame) -> Frame:
        fmt = pixel_format(raw.pixel_format)
        image = unpack(raw.data, fmt, raw.width, raw.height)
        return Frame(
            raw.frame_id, raw.timestamp_ns, image, fmt.name, self.settings_in_force, self.profile.bayer_layout(fmt.name)
        )

    # -- outages ------------------------------------------------------------------------------
    def _reconnect(self, lost: DeviceLost, outage: _Outage) -> None:
        """Reconnect with back-off within the policy's bounds (counted over the whole ``outage``), restore
        and verify the settings, resume acquisition if it was running; else one `DeviceError`."""
        policy = self.policy
        wanted, streaming = self.settings_in_force, self._state.streaming
        self._state.streaming = False
        last: Exception = lost
        while outage.attempts < policy.reconnect_attempts and time.monotonic() - outage.noticed < policy.outage_limit_s:
            left_s = policy.outage_limit_s - (time.monotonic() - outage.noticed)
            time.sleep(min(policy.backoff_s(outage.attempts), max(left_s, 0.0)))
            outage.attempts += 1
            try:
                self.transport.reconnect()
                self._restore(wanted)
                if streaming:
                    self.start()
                self._state.stats.reconnects += 1
                return
            except DeviceError as exc:
                last = exc
        raise DeviceError(
            f"{self.info.device_id}: device lost ({lost}); not back after {outage.attempts} reconnect attempts over "
            f"{time.monotonic() - outage.noticed:.1f} s (limits: {policy.reconnect_attempts} attempts, "
            f"{policy.outage_limit_s:g} s; last: {last})"
        )

    def _restore(self, wanted: Settings) -> None:
        """Apply ``wanted`` to a freshly reconnected device and verify every setting by read-back."""
        self.auto_off()
        self.pixel_format = wanted.pixel_format
        if self.transport.has("BinningHorizontal"):
            self.set_binning(*wanted.binning)
        self.set_roi(wanted.offset_x, wanted.offset_y, wanted.width, wanted.height)
        for key, value in (
            ("exposure_us", wanted.exposure_us),
            ("gain_db", wanted.gain_db),
            ("black_level", wanted.black_level),
        ):
            if value is not None:
                setattr(self, key, value)
        if self._state.frame_rate_set and wanted.frame_rate_hz is not None:
            self.frame_rate_hz = wanted.frame_rate_hz
        self.set_trigger(wanted.trigger)
        problems = wanted.disagreements(self.read_settings()) + self._auto_modes_left_on()
        if problems:
            raise DeviceError(f"{self.info.device_id}: settings not restored after reconnecting: {'; '.join(problems)}")
