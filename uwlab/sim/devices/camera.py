"""Simulated GenICam camera: EMVA 1288 linear sensor model behind an SFNC feature map.

Physics (EMVA Standard 1288 release 4.0, "linear camera model"), per pixel and frame:

* photo-electrons ``μ_p = rate[e-/s] · (1 + PRNU map) · t_exp · f_light`` where ``rate`` is the
  scene's electron-rate map at full light (cos⁴ vignetting and target surround included by the
  scene) and ``f_light`` the light's current flux fraction, read at every frame; the rate map is
  assumed linear in flux (computed once at ``f_light = 1``);
* dark signal ``μ_d = I_dark[e-/s] · t_exp + DSNU map[e-]`` (DSNU: seeded Gaussian fixed
  pattern of std ``dsnu_e``; PRNU: seeded Gaussian gain pattern of std ``prnu_percent``);
* temporal noise: shot noise of ``μ_p + I_dark·t_exp`` (Poisson) plus dark noise ``σ_d`` [e-];
* optional hot pixels (the tank world's ``sensor_realism``): a seeded fraction ``hot_pixel_fraction`` of the
  pixels whose dark current is ``hot_pixel_dark_current_e_per_s``;
* electrons clipped at the full well ``saturation_e``; digital numbers
  ``DN = K0 · 10^(gain_db/20) · e + dark_offset_dn + black_level``, rounded to the sensor's
  ``bit_depth`` and clipped to its range; the output pixel format then shifts the native code
  left or right to its own bit depth (as cameras do for Mono16 / Mono8 output).

Test equipment beyond the linear model (both off by default): ``nonlinearity`` β compresses the
signal (noise included) quadratically, e → e − β e² / saturation_e after the full-well clip, so
that the characteristic curve bends by β at the full well and has slope 1 at zero; and
``dark_current_doubling_c`` makes the dark current double every that many °C around
``temperature_c`` (the Release 3.1 model, EMVA 1288 Release 4.0 Linear eq. 31), see
`SimTruth.at_temperature`.

Binning sums charge of ``bh × bv`` pixels (CCD-style) with one read per binned pixel;
full-well clipping is applied per binned pixel.

Shot noise, default ``shot_noise="gaussian"``: ``N(μ, μ)`` — exact mean and variance, higher
moments approximate (fine above ~20 e-). Standard-normal deviates come from a seeded float32
*noise bank* of ``n_pixels + 2**20`` values read at a random offset every frame: within a frame
all deviates are independent, and a pixel gets a different bank element in each frame, so
spatial and temporal means/variances are those of the model (consecutive frames differ by a
shift of the same bank: do not use cross-frame spatial correlations). ``shot_noise="poisson"``
draws exact Poisson electrons (slow; for small ROIs and low-signal tests).
"""

from __future__ import annotations

import functools
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from uwlab.drivers.camera.interface import DeviceEntry, DeviceLost, FrameTimeout, RawFrame, unknown_device
from uwlab.drivers.camera.pixels import MONO_FORMATS, bayer_formats, pack, pixel_format
from uwlab.errors import ConfigError, DeviceError

NOISE_BANK_MARGIN = 1 << 20
# The brightest 1 % of the scene at half the saturation capacity: where a camera's continuous auto-exposure settles
# (assumed: vendors' targets vary; this one keeps the highlights unclipped).
AUTO_EXPOSURE_FILL = 0.5


@functools.lru_cache(maxsize=2)
def _fixed_pattern(
    resolution_px: tuple[int, int],
    dsnu_e: float,
    prnu_percent: float,
    hot_pixel_fraction: float,
    hot_pixel_dark_current_e_per_s: float,
    dark_current_e_per_s: float,
    seed: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A sensor's fixed pattern drawn from `seed`, read-only: its DSNU [e⁻] and PRNU (gain factor) maps, and its
    dark-current map [e⁻/s] where it has hot pixels (else None). The last two sensors' patterns are kept: the
    simulated rig opens a camera again for each of its sweeps, with the same seed, and a full sensor's maps take
    ~0.1 s to draw."""
    width, height = resolution_px
    rng = np.random.default_rng(seed)
    dsnu = rng.standard_normal((height, width), np.float32) * np.float32(dsnu_e)
    prnu = 1.0 + rng.standard_normal((height, width), np.float32) * np.float32(prnu_percent / 100.0)
    dark = None
    if hot_pixel_fraction > 0:
        hot = np.random.default_rng(seed + 2).random((height, width)) < hot_pixel_fraction
        dark = np.where(hot, hot_pixel_dark_current_e_per_s, dark_current_e_per_s).astype(np.float32)
    for array in (dsnu, prnu, dark):
        if array is not None:
            array.flags.writeable = False
    return dsnu, prnu, dark


@dataclass(frozen=True)
class SimTruth:
    """Ground-truth EMVA 1288 parameters of the simulated sensor (names as in
    `uwlab.model.sensor.SensorProfile`)."""

    name: str
    resolution_px: tuple[int, int]
    bit_depth: int
    K_dn_per_e: float
    dark_offset_dn: float
    dark_noise_e: float
    saturation_e: float
    dark_current_e_per_s: float
    dsnu_e: float
    prnu_percent: float
    exposure_min_us: float
    exposure_max_us: float
    gain_min_db: float
    gain_max_db: float
    pixel_size_um: float = 3.45
    temperature_c: float = 40.0
    nonlinearity: float = 0.0
    dark_current_doubling_c: float | None = None
    hot_pixel_fraction: float = 0.0
    hot_pixel_dark_current_e_per_s: float = 0.0
    bayer: str | None = None

    @classmethod
    def from_sensor_profile(cls, profile: Any, **overrides: Any) -> SimTruth:
        names = {f.name for f in fields(cls)}
        values = {n: getattr(profile, n) for n in names if hasattr(profile, n)}
        values["bayer"] = getattr(profile, "bayer", None) if getattr(profile, "color", False) else None
        values["resolution_px"] = tuple(int(v) for v in values["resolution_px"])
        return cls(**{**values, **overrides})

    def system_gain(self, gain_db: float) -> float:
        """K [DN/e-] at the native bit depth for ``gain_db``."""
        return self.K_dn_per_e * 10.0 ** (gain_db / 20.0)

    def at_temperature(self, temperature_c: float) -> SimTruth:
        """The sensor at another temperature: µ_I = µ_I.ref 2^((T − T_ref)/T_d) (EMVA 1288 Release 4.0 Linear
        eq. 31) with T_d = ``dark_current_doubling_c``; unchanged dark current without a doubling temperature."""
        factor = (
            1.0
            if self.dark_current_doubling_c is None
            else 2.0 ** ((temperature_c - self.temperature_c) / self.dark_current_doubling_c)
        )
        return replace(
            self, temperature_c=float(temperature_c), dark_current_e_per_s=self.dark_current_e_per_s * factor
        )

    def compressed_e(self, electrons):
        """The signal after the test non-linearity: e − β e² / saturation_e (identity for β = 0)."""
        electrons = np.asarray(electrons, float)
        return electrons - self.nonlinearity * electrons**2 / self.saturation_e


@dataclass(frozen=True)
class SensorConfig:
    """Register state that determines an image: ROI and offsets in binned pixels."""

    exposure_us: float
    gain_db: float
    black_level_dn: float
    pixel_format: str
    offset_x: int
    offset_y: int
    width: int
    height: int
    binning_h: int = 1
    binning_v: int = 1


RateMap = Callable[[tuple[int, int]], np.ndarray]


def flat_rate_map(rate_e_per_s: float) -> RateMap:
    """A uniform electron-rate map (flat field), e.g. for tests and the EMVA photon transfer."""
    return lambda shape: np.full(shape, rate_e_per_s, np.float32)


class SimSensor:
    """Renders images of the EMVA 1288 model for a `SensorConfig`.

    ``rate_map(shape_yx)`` returns the electron rate [e-/s] at full light for the full sensor;
    ``light_fraction()`` is read at every frame.
    """

    def __init__(
        self,
        truth: SimTruth,
        rate_map: RateMap,
        light_fraction: Callable[[], float] = lambda: 1.0,
        seed: int = 0,
        shot_noise: str = "gaussian",
    ):
        if shot_noise not in ("gaussian", "poisson"):
            raise ConfigError("shot_noise", shot_noise, "expected 'gaussian' or 'poisson'")
        self.truth = truth
        self.light_fraction = light_fraction
        self.shot_noise = shot_noise
        self.dsnu_map_e, self.prnu_map, self.dark_current_map = _fixed_pattern(
            truth.resolution_px,
            truth.dsnu_e,
            truth.prnu_percent,
            truth.hot_pixel_fraction,
            truth.hot_pixel_dark_current_e_per_s,
            truth.dark_current_e_per_s,
            seed,
        )
        self._rng = np.random.default_rng(seed + 1)
        self._bank = np.empty(0, np.float32)
        self._work = np.empty((0, 0), np.float32)
        self.set_rate_map(rate_map)

    def set_rate_map(self, rate_map: RateMap) -> None:
        """Replace the electron-rate map (e.g. after a lens change in the scene); cached images are dropped,
        so the next frame is rendered from the new map."""
        width, height = self.truth.resolution_px
        rate = np.asarray(rate_map((height, width)), np.float32)
        if rate.shape != (height, width):
            raise ConfigError("rate_map", rate.shape, f"expected shape {(height, width)}")
        self.rate_e_per_s = rate
        self._cache: tuple[Any, tuple[np.ndarray, np.ndarray, float]] | None = None

    def auto_exposure_us(self) -> float:
        """The exposure a camera powered on with continuous auto-exposure has settled at (its power-on
        ExposureTime; uwlab's driver then turns auto-exposure off and keeps it): the brightest 1 % of the scene, as
        lit now, at `AUTO_EXPOSURE_FILL` of the saturation capacity, within the exposure range; the range's
        10 ms (or its nearest end) in the dark."""
        truth = self.truth
        brightest = float(np.quantile(self.rate_e_per_s[::8, ::8], 0.99)) * float(self.light_fraction())
        exposure_us = AUTO_EXPOSURE_FILL * truth.saturation_e / brightest * 1e6 if brightest > 0 else 10000.0
        return min(max(exposure_us, truth.exposure_min_us), truth.exposure_max_us)

    def _dark_electrons(self, cfg: SensorConfig, t: float):
        """Mean dark-current electrons per output pixel (a scalar without hot pixels)."""
        if self.dark_current_map is None:
            return np.float32(self.truth.dark_current_e_per_s * t * cfg.binning_h * cfg.binning_v)
        return self._binned(self.dark_current_map, cfg) * np.float32(t)

    def electrons(self, cfg: SensorConfig, fraction: float) -> tuple[np.ndarray, np.ndarray]:
        """Mean electrons and temporal variance [e-²] per output pixel (before clipping)."""
        t = cfg.exposure_us * 1e-6
        photo = self._binned(self.rate_e_per_s, cfg, self.prnu_map) * np.float32(t * fraction)
        dark = self._dark_electrons(cfg, t)
        mean = photo + dark + self._binned(self.dsnu_map_e, cfg)
        var = photo + dark + np.float32(self.truth.dark_noise_e**2)
        return mean, var

    def expected_dn(self, cfg: SensorConfig, fraction: float = 1.0) -> tuple[np.ndarray, np.ndarray, float]:
        """Mean and std [native DN] per output pixel, and the DN of a full well (before rounding)."""
        k = self.truth.system_gain(cfg.gain_db)
        offset = self.truth.dark_offset_dn + cfg.black_level_dn
        mean_e, var_e = self.electrons(cfg, fraction)
        return (
            mean_e * np.float32(k) + np.float32(offset),
            np.sqrt(var_e) * np.float32(k),
            k * self.truth.saturation_e + offset,
        )

    def render(self, cfg: SensorConfig) -> np.ndarray:
        """One image, decoded, in ``cfg.pixel_format`` (uint8 or uint16, shape (height, width))."""
        fraction = float(self.light_fraction())
        if self.shot_noise == "poisson":
            native = self._render_poisson(cfg, fraction)
        else:
            native = self._render_gaussian(cfg, fraction)
        return self._to_format(native, pixel_format(cfg.pixel_format))

    def _binned(self, full: np.ndarray, cfg: SensorConfig, times: np.ndarray | None = None) -> np.ndarray:
        """The window's output pixels of a full-sensor map (its sensor pixels summed over the binning), of the
        product with `times` (another full-sensor map) when given: only the window's pixels are multiplied."""
        bh, bv = cfg.binning_h, cfg.binning_v
        x0, y0 = cfg.offset_x * bh, cfg.offset_y * bv
        window = np.s_[y0 : y0 + cfg.height * bv, x0 : x0 + cfg.width * bh]
        region = full[window] if times is None else full[window] * times[window]
        if bh == bv == 1:
            return region
        return region.reshape(cfg.height, bv, cfg.width, bh).sum(axis=(1, 3), dtype=np.float32)

    def _maps(self, cfg: SensorConfig, fraction: float) -> tuple[np.ndarray, np.ndarray, float]:
        key = (replace(cfg, pixel_format=""), fraction)
        if self._cache is None or self._cache[0] != key:
            mean, std, cap = self.expected_dn(cfg, fraction)
            self._cache = (key, (mean + np.float32(0.5), std, cap + 0.5))
        return self._cache[1]

    def _deviates(self, n: int) -> np.ndarray:
        if self._bank.size < n + NOISE_BANK_MARGIN:
            self._bank = self._rng.standard_normal(n + NOISE_BANK_MARGIN, np.float32)
        start = int(self._rng.integers(0, self._bank.size - n + 1))
        return self._bank[start : start + n]

    def _render_gaussian(self, cfg: SensorConfig, fraction: float) -> np.ndarray:
        mean, std, cap = self._maps(cfg, fraction)
        if self._work.shape != mean.shape:
            self._work = np.empty(mean.shape, np.float32)
        np.multiply(std, self._deviates(mean.size).reshape(mean.shape), out=self._work)
        self._work += mean
        self._compress(self._work, cfg, cap)
        return self._quantise(self._work, cap)

    def _compress(self, dn_plus_half: np.ndarray, cfg: SensorConfig, cap_plus_half: float) -> None:
        """Apply the test non-linearity (in place) to DN values: clip at the full well, then s − β s² / s_sat for the
        signal s above the offset (s_sat = K · saturation_e)."""
        if not self.truth.nonlinearity:
            return
        k = self.truth.system_gain(cfg.gain_db)
        offset = np.float32(self.truth.dark_offset_dn + cfg.black_level_dn + 0.5)
        np.minimum(dn_plus_half, np.float32(cap_plus_half), out=dn_plus_half)
        dn_plus_half -= offset
        dn_plus_half -= np.float32(self.truth.nonlinearity / (k * self.truth.saturation_e)) * dn_plus_half**2
        dn_plus_half += offset

    def _render_poisson(self, cfg: SensorConfig, fraction: float) -> np.ndarray:
        t = cfg.exposure_us * 1e-6
        poisson_mean = self._binned(self.rate_e_per_s, cfg, self.prnu_map) * (t * fraction)
        poisson_mean = poisson_mean + self._dark_electrons(cfg, t)
        electrons = self._rng.poisson(np.maximum(poisson_mean, 0.0)).astype(np.float32)
        electrons += self._binned(self.dsnu_map_e, cfg)
        electrons += self._rng.standard_normal(electrons.shape, np.float32) * np.float32(self.truth.dark_noise_e)
        k = self.truth.system_gain(cfg.gain_db)
        offset = self.truth.dark_offset_dn + cfg.black_level_dn
        cap = k * self.truth.saturation_e + offset + 0.5
        dn = electrons * np.float32(k) + np.float32(offset + 0.5)
        self._compress(dn, cfg, cap)
        return self._quantise(dn, cap)

    def _quantise(self, dn_plus_half: np.ndarray, cap_plus_half: float) -> np.ndarray:
        top = min(cap_plus_half, (1 << self.truth.bit_depth) - 0.5)
        np.clip(dn_plus_half, 0.0, top, out=dn_plus_half)
        native = np.empty(dn_plus_half.shape, np.uint16)
        np.copyto(native, dn_plus_half, casting="unsafe")
        return native

    def _to_format(self, native: np.ndarray, fmt: Any) -> np.ndarray:
        shift = fmt.bits - self.truth.bit_depth
        if shift > 0:
            native <<= shift
        elif shift < 0:
            native >>= -shift
        return native.astype(fmt.dtype, copy=False)


@dataclass(frozen=True)
class SimFaults:
    """Fault injection: every ``incomplete_every``-th frame arrives incomplete; after
    ``timeout_after`` frames no frame arrives any more; after ``lost_after`` frames, or at the
    ``lost_at_operation``-th device operation (register read or write, command, acquisition
    start, frame fetch; counted from 1 from the transport's creation), the device disappears for ``outage_s``
    seconds and its first ``failed_reconnects`` reconnect attempts fail. A device that comes back
    has power-cycled: every register holds its power-on value. Each loss happens once."""

    incomplete_every: int = 0
    timeout_after: int | None = None
    lost_after: int | None = None
    failed_reconnects: int = 0
    lost_at_operation: int | None = None
    outage_s: float = 0.0


@dataclass
class _Node:
    kind: str
    value: Any = None
    bounds: Callable[[], tuple[float, float]] | None = None
    entries: tuple[str, ...] = ()
    writable: bool = True
    increment: int = 1  # GenICam <Inc>: an integer's values step by it


class SimNodeMap:
    """SFNC feature map of the simulated camera, shared by the in-process transport and the
    GigE Vision server. Writes are range-checked like a device would (`ConfigError`)."""

    def __init__(self, truth: SimTruth, serial: str = "SIM0001", exposure_us: float = 10000.0):
        self.truth = truth
        width, height = truth.resolution_px
        fmts = bayer_formats(truth.bayer) if truth.bayer else MONO_FORMATS
        kind = f"Bayer{truth.bayer}" if truth.bayer else "Mono"
        # a colour sensor's window moves and grows by its 2 × 2 Bayer cell (an odd offset would shift the mosaic
        # under an unchanged PixelFormat), and it does not bin (charge of different filters would mix)
        step, max_binning = (2, 1) if truth.bayer else (1, 4)
        self.nodes: dict[str, _Node] = {
            "DeviceVendorName": _Node("str", "uwlab", writable=False),
            "DeviceModelName": _Node("str", f"SimCam-{truth.name}", writable=False),
            "DeviceSerialNumber": _Node("str", serial, writable=False),
            "DeviceFirmwareVersion": _Node("str", "uwlab-sim-1.0", writable=False),
            "SensorWidth": _Node("int", width, writable=False),
            "SensorHeight": _Node("int", height, writable=False),
            "BinningHorizontal": _Node("int", 1, lambda: (1, max_binning)),
            "BinningVertical": _Node("int", 1, lambda: (1, max_binning)),
            "Width": _Node(
                "int",
                width,
                lambda: (8, width // self.value("BinningHorizontal") - self.value("OffsetX")),
                increment=step,
            ),
            "Height": _Node(
                "int",
                height,
                lambda: (8, height // self.value("BinningVertical") - self.value("OffsetY")),
                increment=step,
            ),
            "OffsetX": _Node(
                "int",
                0,
                lambda: (0, width // self.value("BinningHorizontal") - self.value("Width")),
                increment=step,
            ),
            "OffsetY": _Node(
                "int",
                0,
                lambda: (0, height // self.value("BinningVertical") - self.value("Height")),
                increment=step,
            ),
            "PixelFormat": _Node("enum", f"{kind}8" if truth.bit_depth <= 8 else f"{kind}16", entries=fmts),
            "PayloadSize": _Node("int", 0, writable=False),
            "ExposureTime": _Node(
                "float",
                min(max(exposure_us, truth.exposure_min_us), truth.exposure_max_us),
                lambda: (truth.exposure_min_us, truth.exposure_max_us),
            ),
            "ExposureAuto": _Node("enum", "Continuous", entries=("Off", "Continuous")),
            "Gain": _Node("float", truth.gain_min_db, lambda: (truth.gain_min_db, truth.gain_max_db)),
            "GainAuto": _Node("enum", "Continuous", entries=("Off", "Continuous")),
            "BlackLevel": _Node("float", 0.0, lambda: (0.0, float(1 << max(truth.bit_depth - 2, 1)))),
            "AcquisitionMode": _Node("enum", "Continuous", entries=("Continuous",)),
            "AcquisitionFrameRateEnable": _Node("bool", False),
            "AcquisitionFrameRate": _Node("float", 30.0, lambda: (0.1, 1000.0)),
            "DeviceTemperature": _Node("float", truth.temperature_c, writable=False),
            "TriggerSelector": _Node("enum", "FrameStart", entries=("FrameStart",)),
            "TriggerMode": _Node("enum", "Off", entries=("Off", "On")),
            "TriggerSource": _Node("enum", "Software", entries=("Software",)),
            "AcquisitionStart": _Node("cmd"),
            "AcquisitionStop": _Node("cmd"),
            "TriggerSoftware": _Node("cmd"),
        }

    def _node(self, name: str) -> _Node:
        node = self.nodes.get(name)
        if node is None:
            raise ConfigError("feature", name, "no such feature on the simulated camera")
        return node

    def has(self, name: str) -> bool:
        return name in self.nodes

    def value(self, name: str) -> Any:
        if name == "PayloadSize":
            return self.payload_size()
        return self._node(name).value

    def bounds(self, name: str) -> tuple[float, float] | None:
        node = self._node(name)
        return node.bounds() if node.bounds else None

    def entries(self, name: str) -> tuple[str, ...]:
        return self._node(name).entries

    def set(self, name: str, value: Any) -> None:
        node = self._node(name)
        if not node.writable or node.kind == "cmd":
            raise ConfigError(name, value, "read-only feature")
        node.value = self._checked(name, node, value)
        if name.startswith("Binning"):
            self._fit_roi()

    def _fit_roi(self) -> None:
        """After a binning change, shrink the ROI to the binned sensor (as SFNC devices do)."""
        width, height = self.truth.resolution_px
        for size, offset, full, binning in (
            ("Width", "OffsetX", width, "BinningHorizontal"),
            ("Height", "OffsetY", height, "BinningVertical"),
        ):
            limit = full // self.value(binning)
            self.nodes[size].value = min(self.value(size), limit)
            self.nodes[offset].value = min(self.value(offset), limit - self.value(size))

    def _checked(self, name: str, node: _Node, value: Any) -> Any:
        if node.kind == "enum":
            if value not in node.entries:
                raise ConfigError(name, value, f"allowed: {', '.join(node.entries)}")
            return value
        if node.kind == "bool":
            return bool(value)
        number = int(value) if node.kind == "int" else float(value)
        lo, hi = node.bounds() if node.bounds else (-np.inf, np.inf)
        if not lo <= number <= hi:
            raise ConfigError(name, value, f"allowed range [{lo:g}, {hi:g}]")
        if node.kind == "int" and number % node.increment:
            raise ConfigError(name, value, f"must be a multiple of {node.increment} (the sensor's Bayer cell)")
        return number

    def payload_size(self) -> int:
        return pixel_format(self.value("PixelFormat")).payload_bytes(self.value("Width"), self.value("Height"))

    def sensor_config(self) -> SensorConfig:
        v = self.value
        return SensorConfig(
            v("ExposureTime"),
            v("Gain"),
            v("BlackLevel"),
            v("PixelFormat"),
            v("OffsetX"),
            v("OffsetY"),
            v("Width"),
            v("Height"),
            v("BinningHorizontal"),
            v("BinningVertical"),
        )

    def frame_period_s(self) -> float:
        """Free-run frame period: the exposure, or the frame rate's period when enabled."""
        exposure = self.value("ExposureTime") * 1e-6
        if self.value("AcquisitionFrameRateEnable"):
            return max(exposure, 1.0 / self.value("AcquisitionFrameRate"))
        return exposure

    def run_auto_modes(self) -> None:
        """While ``ExposureAuto`` is Continuous the exposure keeps changing (+5 % a frame,
        wrapping in range), as an auto loop would: measurements need it Off."""
        bounds = self.bounds("ExposureTime")
        if self.value("ExposureAuto") == "Continuous" and bounds is not None:
            lo, hi = bounds
            nxt = self.value("ExposureTime") * 1.05
            self.nodes["ExposureTime"].value = nxt if nxt <= hi else lo


class SimTransport:
    """In-process transport of the simulated camera (backend ``sim``)."""

    backend = "sim"

    def __init__(
        self,
        sensor: SimSensor,
        device_id: str = "sim0",
        faults: SimFaults | None = None,
        clock_ns: Callable[[], int] = time.monotonic_ns,
    ):
        self.sensor = sensor
        self.device_id = device_id
        self.faults = faults or SimFaults()
        self.nodes = self._power_on()
        self._clock_ns = clock_ns
        self._streaming = False
        self._lost = False
        self._back_at = 0.0
        self._closed = False
        self._reconnect_failures = 0
        self._operations = 0
        self._frame_id = 0
        self._produced = 0
        self._next_ts = 0
        self._triggers = 0

    def _power_on(self) -> SimNodeMap:
        return SimNodeMap(
            self.sensor.truth,
            serial=f"SIM{zlib.crc32(self.device_id.encode()) % 10000:04d}",
            exposure_us=self.sensor.auto_exposure_us(),
        )

    @property
    def operations(self) -> int:
        """Device operations so far (what ``SimFaults.lost_at_operation`` counts)."""
        return self._operations

    def cut(self, outage_s: float, failed_reconnects: int = 0) -> None:
        """Make the device disappear now for ``outage_s`` seconds (fault campaigns; any thread)."""
        self._back_at = time.monotonic() + outage_s
        self._reconnect_failures = failed_reconnects
        self._streaming = False
        self._lost = True

    def _alive(self) -> None:
        if self._closed:
            raise DeviceError(f"{self.device_id}: camera is closed")
        self._operations += 1
        if self.faults.lost_at_operation is not None and self._operations >= self.faults.lost_at_operation:
            self.faults = replace(self.faults, lost_at_operation=None)
            self.cut(self.faults.outage_s, self.faults.failed_reconnects)
        if self._lost:
            raise DeviceLost(f"{self.device_id}: device not responding")

    def has(self, name: str) -> bool:
        return self.nodes.has(name)

    def get(self, name: str) -> Any:
        self._alive()
        return self.nodes.value(name)

    def set(self, name: str, value: Any) -> None:
        self._alive()
        if self._streaming and name in (
            "Width",
            "Height",
            "OffsetX",
            "OffsetY",
            "PixelFormat",
            "BinningHorizontal",
            "BinningVertical",
        ):
            raise ConfigError(name, value, "locked while acquiring (TLParamsLocked)")
        self.nodes.set(name, value)

    def bounds(self, name: str) -> tuple[float, float] | None:
        return self.nodes.bounds(name)

    def entries(self, name: str) -> tuple[str, ...]:
        return self.nodes.entries(name)

    def execute(self, name: str) -> None:
        self._alive()
        if name == "TriggerSoftware" and self._streaming:
            self._triggers += 1
        elif name == "AcquisitionStart":
            self.start()
        elif name == "AcquisitionStop":
            self.stop()

    def start(self) -> None:
        self._alive()
        self._streaming = True
        self._next_ts = self._clock_ns()

    def stop(self) -> None:
        self._streaming = False
        self._triggers = 0

    def fetch(self, timeout_s: float) -> RawFrame:
        self._alive()
        faults = self.faults
        if faults.lost_after is not None and self._produced >= faults.lost_after:
            self.faults = replace(faults, lost_after=None)
            self.cut(faults.outage_s, faults.failed_reconnects)
            raise DeviceLost(f"{self.device_id}: device not responding")
        if not self._streaming or (faults.timeout_after is not None and self._produced >= faults.timeout_after):
            raise FrameTimeout(f"{self.device_id}: no frame within {timeout_s:g} s")
        if self.nodes.value("TriggerMode") == "On":
            if self._triggers == 0:
                raise FrameTimeout(f"{self.device_id}: no software trigger received")
            self._triggers -= 1
        return self._produce()

    def _produce(self) -> RawFrame:
        cfg = self.nodes.sensor_config()
        image = self.sensor.render(cfg)
        fmt = pixel_format(cfg.pixel_format)
        data = image if fmt.bits_per_pixel in (8, 16) else pack(image, fmt)
        self._frame_id += 1
        self._produced += 1
        ts = self._next_ts
        self._next_ts += int(self.nodes.frame_period_s() * 1e9)
        self.nodes.run_auto_modes()
        problem = ""
        if self.faults.incomplete_every and self._frame_id % self.faults.incomplete_every == 0:
            data, problem = data.reshape(-1)[: data.size // 2], "half its payload (fault injection)"
        return RawFrame(self._frame_id, ts, cfg.width, cfg.height, cfg.pixel_format, data, problem)

    def reconnect(self) -> None:
        if self._closed:
            raise DeviceError(f"{self.device_id}: camera is closed")
        if not self._lost:
            self._streaming = False
            return
        if time.monotonic() < self._back_at or self._reconnect_failures > 0:
            self._reconnect_failures = max(self._reconnect_failures - 1, 0)
            raise DeviceLost(f"{self.device_id}: no answer")
        self.nodes = self._power_on()
        self._lost = False
        self._streaming = False
        self._triggers = 0

    def close(self) -> None:
        self._streaming = False
        self._closed = True


def sensor_from_rig(
    config: str | None = None, seed: int = 0, shot_noise: str = "gaussian", rig_state: str | None = None
) -> SimSensor:
    """The simulated sensor of a rig description (default rig when ``config`` is None): sensor
    profile, irradiance map and light state all come from `uwlab.sim.scene`;
    ``rig_state`` is the light-state file shared with the simulated light (`RigState`)."""
    from uwlab.sim.rig_state import RigState
    from uwlab.sim.scene import RigScene

    scene = RigScene.from_toml(config, RigState(rig_state) if rig_state else None)
    truth = SimTruth.from_sensor_profile(scene.sensor, **scene.sensor_realism())
    return SimSensor(
        truth, lambda shape: scene.electron_rate_map(shape, 1.0), scene.flux_fraction, seed=seed, shot_noise=shot_noise
    )


SIM_DEVICE_IDS = ("sim0",)


def discover(config: str | None = None, sensor: SimSensor | None = None, **_: Any) -> list[DeviceEntry]:
    """The in-process simulated camera(s) of the rig."""
    truth = (sensor or sensor_from_rig(config)).truth
    nodes = SimNodeMap(truth)
    return [
        DeviceEntry("sim", dev, "uwlab", nodes.value("DeviceModelName"), f"SIM{zlib.crc32(dev.encode()) % 10000:04d}")
        for dev in SIM_DEVICE_IDS
    ]


def open_transport(
    device_id: str | None = None,
    config: str | None = None,
    seed: int = 0,
    faults: SimFaults | None = None,
    sensor: SimSensor | None = None,
    shot_noise: str = "gaussian",
    rig_state: str | None = None,
    **_: Any,
) -> SimTransport:
    """Open the simulated camera ``device_id`` (default ``sim0``); ``sensor`` injects a
    ready-made `SimSensor` (ground truth, rate map, light), else the rig ``config`` is used."""
    device_id = device_id or SIM_DEVICE_IDS[0]
    if device_id not in SIM_DEVICE_IDS:
        raise unknown_device("sim", device_id, SIM_DEVICE_IDS)
    return SimTransport(sensor or sensor_from_rig(config, seed, shot_noise, rig_state), device_id, faults)
