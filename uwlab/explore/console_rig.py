"""The rig behind the console (docs/console.md): its devices kept open, a background thread grabbing frames into a
frame buffer, what each frame shows (statistics, histogram, clipped pixels, sharpness) and the sweep runs.

- **Live view** (`Live`): the camera streams continuously in a thread of its own (at most ``max_fps`` frames a
  second); each frame's view (`FrameView`) is computed there, so requests only read the latest one. Settings,
  lights and the spectrometer go through one lock with the grabbing, so nothing is sent to a device while another
  request uses it; every answer is a read-back. Each change (a frame, a setting, a run's point or state) is told to
  the event streams (`Changes`), which wait for one instead of polling: a watcher costs nothing between changes.
- **Focusing aids** (`sharpness`): the Tenengrad (mean squared Sobel gradient) and the variance of the Laplacian
  of the ROI, each divided by the ROI's squared mean so that the number is the same across exposures and gains
  (both scale as the square of the signal). Tenengrad: J. M. Tenenbaum, *Accommodation in computer vision*, PhD
  thesis, Stanford, 1970; variance of the Laplacian: J. L. Pech-Pacheco et al., "Diatom autofocusing in brightfield
  microscopy: a comparative study", ICPR 2000; both compared in S. Pertuz, D. Puig, M. A. Garcia, "Analysis of
  focus measure operators for shape-from-focus", Pattern Recognition 46 (2013) 1415–1432. The model's focus setting
  and close-up lens come from `uwlab.model.port_field.trace_design` (what ``uwlab port trace`` prints).
- **Runs** (`Runs`): a plan run by the sweep engine (`uwlab.experiments.acquisition.sweep.SweepRunner`) into a
  dataset exactly as ``uwlab sweep`` runs it (`uwlab.experiments.acquisition.session`: the dataset opened first,
  then the rig, lights to their safe state on any exit). The engine calls back after every recorded point; there a
  pause takes effect (every light switched off and read back: its safe state) and waits, resume lets the next point
  run (the engine sets the light again before every point), abort ends the run (the dataset stays valid and
  resumable with ``uwlab sweep --resume``). While a run holds the rig, the live view releases its devices (a camera
  and an instrument have one owner) and takes them back when the run ends. Each run carries the model's predicted
  band for its plan (`prediction_of`: `uwlab.experiments.calibration.planned`, from the design's priors or a fit's
  posterior), computed when it starts.
"""

from __future__ import annotations

import io
import math
import threading
import time
import uuid
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any
from collections.abc import Callable

import numpy as np
from scipy import ndimage

from uwlab.drivers.camera import Camera, Frame, open_camera
from uwlab.drivers.camera.pixels import bayer_sites
from uwlab.errors import ConfigError, UwlabError
from uwlab.experiments.acquisition.grab import Settings, parse_roi
from uwlab.experiments.acquisition.plan import Plan, load_plan
from uwlab.experiments.acquisition.readbacks import light_state
from uwlab.experiments.acquisition.session import make_rig, open_target, record_safe_state
from uwlab.experiments.acquisition.spectra import irradiance_w_m2
from uwlab.experiments.acquisition.sweep import Progress, SweepRunner
from uwlab.experiments.saturation import ClipLevel, adc_max_dn, frame_clip_level
from uwlab.model.data import read_toml
from uwlab.model.schema import ExposureUs, GainDb, check
from uwlab.model.sensor import SensorProfile

if TYPE_CHECKING:
    from uwlab.experiments.acquisition.rigs import HardwareRig
    from uwlab.experiments.acquisition.sim_rig import SimRig

PREVIEW_MAX_PX = 800  # the browser's image: the frame decimated to at most this many pixels a side
HISTOGRAM_BINS = 256
TRACE_LENGTH = 600  # sharpness values kept (a minute at 10 frames a second)
PEAKING_SIGMA = 3.0  # focus peaking: gradients beyond the mean + this many standard deviations of the preview's
RUN_STATES = ("running", "paused", "done", "aborted", "failed")


def sharpness(image: np.ndarray) -> dict[str, float]:
    """Focus measures of ``image`` (module docstring), each normalised by the squared mean: ``tenengrad`` (mean of
    Gx² + Gy², Sobel) and ``laplacian`` (variance of the 3 × 3 Laplacian); 0 for a black or tiny image.

    >>> edge = np.tile(np.r_[np.full(8, 100.0), np.full(8, 300.0)], (16, 1))
    >>> a, b = sharpness(edge), sharpness(2 * edge)
    >>> round(a["tenengrad"], 6) == round(b["tenengrad"], 6), a["tenengrad"] > 0
    (True, True)
    """
    data = np.asarray(image, np.float32)
    mean = float(data.mean()) if data.size else 0.0
    if data.shape[0] < 3 or data.shape[1] < 3 or mean <= 0:
        return {"tenengrad": 0.0, "laplacian": 0.0}
    gx, gy = ndimage.sobel(data, axis=1), ndimage.sobel(data, axis=0)
    inner = (slice(1, -1), slice(1, -1))  # the border's gradients see the padding, not the scene
    tenengrad = float(np.mean(gx[inner] ** 2 + gy[inner] ** 2, dtype=np.float64))
    laplacian = float(np.var(ndimage.laplace(data)[inner], dtype=np.float64))
    return {"tenengrad": tenengrad / mean**2, "laplacian": laplacian / mean**2}


def check_roi(roi: tuple[int, int, int, int], shape: tuple[int, ...], key: str = "roi") -> tuple[int, int, int, int]:
    """``roi`` (x, y, w, h) when it lies inside an image of ``shape``, else a `ConfigError` naming ``key``."""
    x, y, w, h = roi
    if x + w > shape[1] or y + h > shape[0]:
        raise ConfigError(key, list(roi), f"outside the {shape[1]} x {shape[0]} frame")
    return roi


def default_roi(shape: tuple[int, ...]) -> tuple[int, int, int, int]:
    """A quarter of the frame's width and height, centred (a focusing patch: small enough to follow live)."""
    h, w = shape[:2]
    return 3 * w // 8, 3 * h // 8, max(w // 4, 1), max(h // 4, 1)


def preview_step(shape: tuple[int, ...], max_px: int = PREVIEW_MAX_PX) -> int:
    """The decimation that brings a frame's longest side to at most ``max_px`` pixels."""
    return max(1, math.ceil(max(shape[:2]) / max_px))


CLIP_RGB = (255, 0, 40)
PEAKING_RGB = (40, 230, 40)
GREYS = 254  # palette indices 0..253: grey levels; 254: clipped; 255: an edge (focus peaking)
PALETTE = [v for level in range(GREYS) for v in (round(level * 255 / (GREYS - 1)),) * 3] + [*CLIP_RGB, *PEAKING_RGB]


def preview(image: np.ndarray, clip_dn: float, step: int, clip: bool = True, peaking: bool = False) -> np.ndarray:
    """The frame decimated by ``step`` as indices into `PALETTE` (grey from black to the clip level); clipped
    pixels painted red, and with ``peaking`` the strongest edges green (focus peaking)."""
    small = np.asarray(image[::step, ::step], np.float32)
    out = np.clip(small * ((GREYS - 1) / max(clip_dn, 1.0)), 0, GREYS - 1).astype(np.uint8)
    if peaking and min(small.shape) >= 3:
        magnitude = np.hypot(ndimage.sobel(small, axis=1), ndimage.sobel(small, axis=0))
        out[magnitude > magnitude.mean() + PEAKING_SIGMA * magnitude.std()] = GREYS + 1
    if clip:
        out[small >= clip_dn] = GREYS
    return out


def png(indices: np.ndarray, compress_level: int = 0) -> bytes:
    """A `preview` as a palette PNG (one byte a pixel; by default stored without compression, which costs well under
    a millisecond where deflate costs ten: the browser gets many a second over the loopback)."""
    from PIL import Image

    picture = Image.fromarray(indices)
    picture.putpalette(PALETTE)
    out = io.BytesIO()
    picture.save(out, format="PNG", compress_level=compress_level)
    return out.getvalue()


def histograms(image: np.ndarray, bayer: str | None, adc_max: float, step: int) -> dict[str, list[int]]:
    """Counts of ``HISTOGRAM_BINS`` equal bins over [0, adc_max] per channel (``mono``, or R, G, B of a Bayer
    mosaic, each over its own sites), from every ``step``-th cell of the frame."""
    cell = 2 * max(1, step // 2) if bayer else step
    planes = {"mono": image[::cell, ::cell]} if bayer is None else _bayer_planes(image, bayer, cell)
    scale = HISTOGRAM_BINS / (adc_max + 1.0)
    return {
        name: np.bincount(
            np.minimum((plane.ravel() * scale).astype(np.int64), HISTOGRAM_BINS - 1), minlength=HISTOGRAM_BINS
        ).tolist()
        for name, plane in planes.items()
    }


def _bayer_planes(image: np.ndarray, bayer: str, cell: int) -> dict[str, np.ndarray]:
    """Each colour's sites of a Bayer mosaic in every ``cell``-th (even) row and column."""
    return {
        colour: np.concatenate([image[row::cell, col::cell].ravel() for row, col in sites])
        for colour, sites in bayer_sites(bayer).items()
    }


@dataclass
class FrameView:
    """What the console shows of one frame: the frame, its clip level and statistics (`as_json`)."""

    frame: Frame
    clip: ClipLevel
    stats: dict[str, Any]
    grabbed_s: float  # time.time() when the frame arrived
    _png: dict = field(default_factory=dict, repr=False)

    def png(self, scale: int | None, clip: bool, peaking: bool) -> bytes:
        """The frame as PNG: decimated for the browser (``scale`` None) or by ``scale`` (1: full resolution)."""
        step = preview_step(self.frame.image.shape) if scale is None else scale
        key = (step, clip, peaking)
        if key not in self._png:
            self._png = {key: png(preview(self.frame.image, self.clip.dn, step, clip, peaking), 0 if step > 1 else 1)}
        return self._png[key]


def frame_view(
    frame: Frame, sensor: SensorProfile | None, roi: tuple[int, int, int, int], fps: float, grabbed_s: float
) -> FrameView:
    """The statistics of ``frame`` (whole frame: mean, saturated fraction by the clip level of
    `uwlab.experiments.saturation`, histograms; the ROI: mean, variance, SNR and sharpness)."""
    image = frame.image
    step = preview_step(image.shape)
    clip = frame_clip_level(frame, sensor, image[::step, ::step])
    x, y, w, h = roi
    crop = image[y : y + h, x : x + w]
    mean = float(crop.mean(dtype=np.float64)) if crop.size else 0.0
    variance = float(crop.var(dtype=np.float64)) if crop.size else 0.0
    focus = sharpness(crop)
    s = frame.settings
    stats = {
        "frame_id": frame.frame_id,
        "t_grab_s": grabbed_s,
        "width": int(image.shape[1]),
        "height": int(image.shape[0]),
        "pixel_format": frame.pixel_format,
        "exposure_us": s.exposure_us,
        "gain_db": s.gain_db,
        "mean_dn": float(image.mean(dtype=np.float64)),
        "saturated_fraction": clip.fraction(image),
        "clip_level_dn": clip.dn,
        "clip_source": clip.source,
        "sharpness": focus["tenengrad"],
        "sharpness_laplacian": focus["laplacian"],
        "fps": fps,
        "roi": {
            "x": x,
            "y": y,
            "w": w,
            "h": h,
            "mean_dn": mean,
            "variance_dn2": variance,
            "snr": mean / math.sqrt(variance) if variance > 0 else None,
        },
        "histogram": {
            "bins_dn": HISTOGRAM_BINS,
            "max_dn": adc_max_dn(frame.pixel_format),
            "counts": histograms(image, frame.bayer, adc_max_dn(frame.pixel_format), step),
        },
    }
    return FrameView(frame, clip, stats, grabbed_s)


@dataclass
class Devices:
    """The devices the live view holds: the camera, the lights by name, the spectrometer (or None), and what closes
    them (the rig's context: lights to their safe state)."""

    camera: Camera
    lights: dict[str, Any]
    spectrometer: Any
    close: Any


class Source:
    """Where the console's devices come from: the simulated rig of a rig file (``sim``) or the devices a sweep plan
    names (its first sweep's camera, its [[lights]] and spectrometer)."""

    def __init__(self, path: Path, sim: bool, seed: int = 0):
        self.path, self.sim, self.seed = Path(path), sim, seed
        raw = read_toml(self.path, "RIG.toml")
        self.plan: Plan | None = load_plan(self.path) if "sweep" in raw else None
        if self.plan is None and not sim:
            raise ConfigError(
                "RIG.toml", str(path), "a rig file is simulated only (--sim); the tank's devices are named by a plan"
            )
        self.rig_path = self.plan.rig_path if self.plan is not None else self.path
        from uwlab.experiments.acquisition.grab import sensor_for

        self.sensor: SensorProfile | None = (
            self.plan.sweeps[0].design.sensor if self.plan is not None else sensor_for("sim", None, str(self.rig_path))
        )

    def design(self):
        """The rig's design (the model's view of it: port, lens, target distance)."""
        if self.plan is not None:
            return self.plan.sweeps[0].design
        from uwlab.sim.scene import RigScene

        return RigScene.from_toml(self.rig_path).design

    def open(self) -> Devices:
        """The devices, open (the simulated rig's simulators started); `Devices.close` releases them."""
        rig: SimRig | HardwareRig
        sim_rig: SimRig | None = None
        device_id: str | None
        if self.sim:
            from uwlab.experiments.acquisition.sim_rig import SimRig

            sim_rig = rig = SimRig(self.rig_path, seed=self.seed, lights=self.plan.lights if self.plan else ())
            options: dict[str, Any] = {"config": str(self.rig_path), "seed": self.seed}
            backend, device_id = "sim", "sim0"
        else:
            from uwlab.experiments.acquisition.rigs import HardwareRig

            assert self.plan is not None  # a rig file without --sim is refused in __init__
            rig = HardwareRig(self.plan, None)
            spec = self.plan.sweeps[0].camera
            options, backend, device_id = {"policy": spec.policy()}, spec.backend, spec.device_id
        rig.__enter__()
        try:
            if sim_rig is not None:  # the camera sees the simulated light through the rig's shared state
                options["rig_state"] = str(sim_rig.rig_state_path)
            camera = open_camera(backend, device_id, **options)
        except BaseException:
            rig.__exit__(None, None, None)
            raise

        def close() -> None:
            try:
                camera.close()
            finally:
                rig.__exit__(None, None, None)

        return Devices(camera, dict(rig.lights), rig.spectrometer, close)


def focus_model(design) -> dict[str, Any]:
    """What the model says about focus for the rig's port and target distance (``uwlab port trace``'s focusing
    aids): the target's image distance, the focus setting and the close-up lens, the depth of field."""
    from uwlab.model.port_field import trace_design

    aid = trace_design(design)["focus"]
    return {
        "target_distance_m": float(design["operation.altitude_m"]),
        "port": str(design["housing.port"]),
        "image_distance_m": aid["image_distance_m"],
        "setting_m": aid["setting_m"],
        "close_up_lens_dpt": aid["close_up_lens_dpt"],
        "dof_m": aid["dof_m"],
    }


class Changes:
    """What the page shows changed (a frame, a setting, a run): `notify` calls every subscriber, from whichever thread
    made the change (the event streams wait for it instead of polling, so a watcher costs nothing between changes)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._subscribers: set[Callable[[], None]] = set()

    def subscribe(self, callback: Callable[[], None]) -> None:
        with self._lock:
            self._subscribers.add(callback)

    def unsubscribe(self, callback: Callable[[], None]) -> None:
        with self._lock:
            self._subscribers.discard(callback)

    def notify(self) -> None:
        with self._lock:
            subscribers = list(self._subscribers)
        for callback in subscribers:
            callback()


class Live:
    """The live view (module docstring): ``start`` opens the devices and the grabbing thread, ``close`` stops it
    and releases the devices (lights to their safe state)."""

    def __init__(self, source: Source, max_fps: float = 12.0):
        self.source = source
        self.max_fps = max_fps
        self.lock = threading.RLock()  # every use of a device
        self.devices: Devices | None = None
        self.latest: FrameView | None = None
        self.roi: tuple[int, int, int, int] | None = None
        self.trace: deque[tuple[float, float, float]] = deque(maxlen=TRACE_LENGTH)
        self.best = {"tenengrad": 0.0, "laplacian": 0.0}
        self.seq = 0  # bumped with every new frame view
        self.settings_seq = 0  # bumped with every change of a setting or a light
        self.changes = Changes()  # notified after each bump of these and of the runs' `Runs.seq`
        self.error: str | None = None
        self.released = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._times: deque[float] = deque(maxlen=20)
        self._focus: dict[str, Any] | None = None

    # -- life ------------------------------------------------------------------------------------
    def start(self) -> None:
        with self.lock:
            self.devices = self.source.open()
            self.released = False
            self._changed()
        self._stop.clear()
        self._thread = threading.Thread(target=self._loop, name="console-live", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30)
            self._thread = None
        with self.lock:
            if self.devices is not None:
                devices, self.devices = self.devices, None
                devices.close()

    def release(self) -> None:
        """Give the devices up (a run takes the rig); `start` takes them back."""
        self.close()
        self.released = True
        self.settings_seq += 1
        self.changes.notify()

    def _loop(self) -> None:
        period = 1.0 / self.max_fps if self.max_fps > 0 else 0.0
        while not self._stop.is_set():
            began = time.monotonic()
            try:
                self._grab()
                self.error = None
            except UwlabError as exc:
                self.error = str(exc)
                self._stop.wait(0.5)
            self._stop.wait(max(0.0, period - (time.monotonic() - began)))

    def _grab(self) -> None:
        with self.lock:
            if self.devices is None:
                return
            frame = next(iter(self.devices.camera.stream(1)))
        arrived = time.time()
        self._times.append(time.monotonic())
        fps = (len(self._times) - 1) / (self._times[-1] - self._times[0]) if len(self._times) > 1 else 0.0
        shape = frame.image.shape
        if self.roi is None or self.roi[0] + self.roi[2] > shape[1] or self.roi[1] + self.roi[3] > shape[0]:
            self.roi = default_roi(shape)
        view = frame_view(frame, self.source.sensor, self.roi, fps, arrived)
        for key, stat in (("tenengrad", "sharpness"), ("laplacian", "sharpness_laplacian")):
            self.best[key] = max(self.best[key], view.stats[stat])
        view.stats["sharpness_best"] = self.best["tenengrad"]
        view.stats["sharpness_laplacian_best"] = self.best["laplacian"]
        self.trace.append((arrived, view.stats["sharpness"], view.stats["sharpness_laplacian"]))
        self.latest = view
        self.seq += 1
        self.changes.notify()

    def _devices(self) -> Devices:
        if self.devices is None:
            raise ConfigError("rig", None, "a run holds the rig: its devices come back when the run ends")
        return self.devices

    # -- camera ----------------------------------------------------------------------------------
    def camera_readback(self) -> dict[str, Any]:
        with self.lock:
            camera = self._devices().camera
            s = camera.read_settings()
            info = camera.info
        return {
            "model": info.model,
            "vendor": info.vendor,
            "backend": info.backend,
            "exposure_us": s.exposure_us,
            "gain_db": s.gain_db,
            "pixel_format": s.pixel_format,
            "pixel_formats": list(camera.pixel_formats),
            "width": s.width,
            "height": s.height,
            "offset_x": s.offset_x,
            "offset_y": s.offset_y,
            "sensor_width": info.sensor_width,
            "sensor_height": info.sensor_height,
        }

    def set_camera(self, body: dict[str, Any]) -> dict[str, Any]:
        """Apply ``exposure_us``, ``gain_db``, ``pixel_format`` and ``roi`` ([x, y, w, h] or "x,y,w,h") within the
        plausibility limits and the camera's own (`uwlab.experiments.acquisition.grab.Settings`); the read-back."""
        unknown = sorted(set(body) - {"exposure_us", "gain_db", "pixel_format", "roi"})
        if unknown:
            raise ConfigError(
                unknown[0], body[unknown[0]], "not a camera setting (exposure_us, gain_db, pixel_format, roi)"
            )
        for key in ("exposure_us", "gain_db"):
            value = body.get(key)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int | float)):
                raise ConfigError(key, value, "must be a number")
        pixel = body.get("pixel_format")
        if pixel is not None and not isinstance(pixel, str):
            raise ConfigError("pixel_format", pixel, "must be a pixel format name")
        roi = body.get("roi")
        if roi is not None:
            if isinstance(roi, list) and all(isinstance(v, int) and not isinstance(v, bool) for v in roi):
                roi = ",".join(str(v) for v in roi)
            if not isinstance(roi, str):
                raise ConfigError("roi", roi, "expected [x, y, w, h] in pixels")
            roi = parse_roi(roi)
        settings = Settings(body.get("exposure_us"), body.get("gain_db"), pixel, roi)
        for key, kind in (("exposure_us", ExposureUs), ("gain_db", GainDb)):
            if body.get(key) is not None:
                check(kind, body[key], key)  # plausibility limits before anything is sent
        with self.lock:
            camera = self._devices().camera
            if pixel is not None and pixel not in camera.pixel_formats:
                raise ConfigError(
                    "pixel_format", pixel, f"not offered by the camera ({', '.join(camera.pixel_formats)})"
                )
            if roi is not None:
                info = camera.info
                check_roi(roi, (info.sensor_height, info.sensor_width))
            camera.stop()  # formats and windows change only while the camera is idle; the next grab restarts it
            settings.apply(camera)
            self._changed()
        if roi is not None:
            self.roi = None
        return self.camera_readback()

    def set_view_roi(self, body: Any) -> dict[str, Any]:
        """The ROI of the statistics and the sharpness, [x, y, w, h] inside the frame."""
        roi = body.get("roi") if isinstance(body, dict) else None
        if not (
            isinstance(roi, list) and len(roi) == 4 and all(isinstance(v, int) and not isinstance(v, bool) for v in roi)
        ):
            raise ConfigError("roi", roi, "expected [x, y, w, h] in pixels")
        parsed = parse_roi(",".join(str(v) for v in roi))
        latest = self.latest
        if latest is not None:
            check_roi(parsed, latest.frame.image.shape)
        self.roi = parsed
        self.reset_focus()
        return {"roi": list(parsed)}

    def _changed(self) -> None:
        """A setting or a light changed: the page hears of it, and the sharpness trace and its best start over
        (a best value from other settings — a darker image's noise reads sharp — would mislead)."""
        self.settings_seq += 1
        self.reset_focus()
        self.changes.notify()

    def reset_focus(self) -> None:
        self.best = {"tenengrad": 0.0, "laplacian": 0.0}
        self.trace.clear()

    def focus(self) -> dict[str, Any]:
        """The sharpness trace, its best values and the model's focus setting for the rig."""
        if self._focus is None:
            self._focus = focus_model(self.source.design())
        trace = list(self.trace)
        return {
            "metric": "tenengrad / mean^2 (Sobel), variance of the Laplacian / mean^2, over the ROI",
            "t_s": [t for t, _, _ in trace],
            "tenengrad": [v for _, v, _ in trace],
            "laplacian": [v for _, _, v in trace],
            "best_tenengrad": self.best["tenengrad"],
            "best_laplacian": self.best["laplacian"],
            "roi": list(self.roi) if self.roi else None,
            "model": self._focus,
        }

    # -- lights and spectrometer ------------------------------------------------------------------
    def lights(self) -> dict[str, Any]:
        with self.lock:
            return {name: self._light(light) for name, light in self._devices().lights.items()}

    @staticmethod
    def _light(light) -> dict[str, Any]:
        return {**light_state(light), "safe_state": {"on": False}, "identity": light.identity()}

    def set_light(self, name: str, body: Any) -> dict[str, Any]:
        if not isinstance(body, dict):
            raise ConfigError("light", body, 'give {"on": true|false, "level": 0..1}')
        unknown = sorted(set(body) - {"on", "level"})
        if unknown:
            raise ConfigError(unknown[0], body[unknown[0]], "not a light setting (on, level)")
        on, level = body.get("on"), body.get("level")
        if on is not None and not isinstance(on, bool):
            raise ConfigError("on", on, "must be true or false")
        if level is not None and (
            isinstance(level, bool) or not isinstance(level, int | float) or not 0.0 <= level <= 1.0
        ):
            raise ConfigError("level", level, "must be a number in [0, 1]")
        with self.lock:
            lights = self._devices().lights
            if name not in lights:
                raise ConfigError("light", name, f"not on this rig (its lights: {', '.join(lights)})")
            light = lights[name]
            if level is not None:
                light.set_level(float(level))
            if on is not None:
                light.set_output(on)
            self._changed()
            return {**self._light(light), "set": {"on": on, "level": level}}

    def spectrum(self) -> dict[str, Any]:
        with self.lock:
            spectrometer = self._devices().spectrometer
            if spectrometer is None:
                raise ConfigError("spectrometer", None, "the rig has no spectrometer")
            wavelength_nm, irradiance = spectrometer.read_spectrum()
            readback = spectrometer.readback()
            return {
                "model": spectrometer.identity(),
                "wavelength_nm": wavelength_nm,
                "irradiance_w_m2_nm": irradiance,
                "irradiance_w_m2": irradiance_w_m2(wavelength_nm, irradiance),
                "saturated": bool(spectrometer.last_saturated),
                "integration_ms": readback.integration_ms,
                "averaging": readback.averaging,
            }

    def rig(self) -> dict[str, Any]:
        if self.devices is None:
            return {"camera": None, "lights": {}, "spectrometer": None, "held_by_run": self.released}
        with self.lock:
            spectrometer = self._devices().spectrometer
            return {
                "camera": self.camera_readback(),
                "lights": self.lights(),
                "spectrometer": None if spectrometer is None else {"model": spectrometer.identity()},
                "held_by_run": False,
                "sim": self.source.sim,
            }


def prediction_of(plan: Plan, fit: str | None) -> dict[str, Any]:
    """The model's band for ``plan`` (`uwlab.experiments.calibration.planned.predicted_bands`): from the fit
    directory ``fit`` (a `ConfigError` when it is no fit of this plan's configurations), else from the design's
    priors — a design the model cannot predict answers its reason as ``error`` and no configurations (the run goes
    ahead without a band)."""
    from uwlab.experiments.calibration.planned import predicted_bands

    if fit is not None:
        return predicted_bands(plan, fit.strip())
    try:
        return predicted_bands(plan)
    except UwlabError as exc:
        return {"source": "design", "configurations": [], "skipped": {}, "error": str(exc).splitlines()[0]}


class RunAborted(Exception):
    """Raised in the engine's progress callback to end a run the operator aborted."""


@dataclass
class Run:
    """A plan running into a dataset (`Runs`), its state one of `RUN_STATES`."""

    id: str
    plan: Plan
    out: Path
    state: str = "running"
    points_done: int = 0
    points_total: int = 0
    points: list[dict] = field(default_factory=list)
    faults: list[str] = field(default_factory=list)
    recoveries: dict[str, int] = field(default_factory=dict)
    lights_safe: dict[str, bool] | None = None
    started_s: float = field(default_factory=time.monotonic)
    paused_for_s: float = 0.0
    first_done: int = 0
    want: str = "run"  # run, pause, abort
    began_s: float | None = None  # time.monotonic() when the run took the rig, and when it ended
    ended_s: float | None = None
    prediction: dict = field(default_factory=dict)  # the model's band for the plan (`predicted_bands`)
    cpu_began: tuple[float, float] | None = None  # CPU seconds of the console and of the run's thread then
    cpu_ended: tuple[float, float] | None = None
    cond: threading.Condition = field(default_factory=threading.Condition)

    def eta_s(self) -> float | None:
        measured = self.points_done - self.first_done
        if self.state not in ("running", "paused") or measured <= 0:
            return None
        per_point = (time.monotonic() - self.started_s - self.paused_for_s) / measured
        return per_point * (self.points_total - self.points_done)

    def _cpu(self) -> dict[str, float | None]:
        """``cpu_s``: the console process's CPU seconds while the run held the rig (the live view stopped: the run
        and the requests served meanwhile); ``run_cpu_s``: the run's own thread's (the engine, the rig's drivers)."""
        if self.cpu_began is None or self.cpu_ended is None:  # known once the run has ended
            return {"cpu_s": None, "run_cpu_s": None}
        (process0, thread0), (process1, thread1) = self.cpu_began, self.cpu_ended
        return {"cpu_s": process1 - process0, "run_cpu_s": thread1 - thread0}

    def as_json(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "plan": str(self.plan.path),
            "out": str(self.out),
            "state": self.state,
            "points_done": self.points_done,
            "points_total": self.points_total,
            "prediction_source": self.prediction.get("source"),
            "eta_s": self.eta_s(),
            "elapsed_s": None if self.began_s is None else (self.ended_s or time.monotonic()) - self.began_s,
            **self._cpu(),
            "faults": list(self.faults),
            "recoveries": dict(self.recoveries),
            "lights_safe_state": self.lights_safe,
            "points": list(self.points),
        }


class Runs:
    """The runs of this console (one at a time: they share the rig with the live view)."""

    def __init__(self, live: Live, sim: bool, seed: int = 0):
        self.live, self.sim, self.seed = live, sim, seed
        self.runs: dict[str, Run] = {}
        self.seq = 0
        self._lock = threading.Lock()
        self._rig = threading.Lock()

    def active(self) -> Run | None:
        return next((r for r in self.runs.values() if r.state in ("running", "paused")), None)

    def get(self, run_id: str) -> Run:
        if run_id not in self.runs:
            raise ConfigError("run", run_id, "no such run")
        return self.runs[run_id]

    def start(self, body: Any) -> Run:
        """Validate the plan (and the fit directory of the predicted band) and open the dataset (so bad input is
        refused now), then run it in a thread."""
        if not isinstance(body, dict) or not isinstance(body.get("plan"), str):
            raise ConfigError("plan", None, 'give {"plan": "PATH.toml", "out": "DIR", "fit": "FIT_DIR" (optional)}')
        out, fit = body.get("out"), body.get("fit")
        if out is not None and not isinstance(out, str):
            raise ConfigError("out", out, "must be a directory path")
        if fit is not None and (not isinstance(fit, str) or not fit.strip()):
            raise ConfigError("fit", fit, "must be a `uwlab fit` output directory")
        with self._lock:
            if (active := self.active()) is not None:
                raise ConfigError("run", active.id, "a run is in progress: pause, resume or abort it first")
            plan = load_plan(body["plan"])
            prediction = prediction_of(plan, fit)
            dataset = open_target(plan, out, sim=self.sim, purpose="uwlab console")
            run = Run(
                uuid.uuid4().hex[:12],
                plan,
                Path(dataset.root),
                points_total=plan.total_points(),
                prediction=prediction,
            )
            self.runs[run.id] = run
            self._changed()
        threading.Thread(target=self._run, args=(run, dataset), name=f"console-run-{run.id}", daemon=True).start()
        return run

    def _run(self, run: Run, dataset) -> None:
        with self._rig:  # one run at a time owns the rig, until the live view has it back
            self._run_holding_the_rig(run, dataset)

    def _run_holding_the_rig(self, run: Run, dataset) -> None:
        self.live.release()
        run.began_s, run.cpu_began = time.monotonic(), (time.process_time(), time.thread_time())
        try:
            with dataset:
                rig = make_rig(run.plan, self.sim, None, self.seed)
                try:
                    with rig:
                        SweepRunner(run.plan, dataset, rig, lambda event: self._progress(run, rig, event)).run()
                except BaseException:
                    record_safe_state(dataset, rig, quiet=True)
                    raise
                finally:
                    run.lights_safe = dict(rig.safe_states)
                record_safe_state(dataset, rig)
            run.state = "done"
        except RunAborted:
            run.state = "aborted"
        except Exception as exc:  # the run's end, shown on the page and in GET /api/runs/ID
            run.faults.append(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
            run.state = "failed"
        finally:
            run.ended_s, run.cpu_ended = time.monotonic(), (time.process_time(), time.thread_time())
            self._changed()
            try:
                self.live.start()
            except Exception as exc:
                self.live.error = str(exc)

    def _progress(self, run: Run, rig, event: Progress) -> None:
        """After each recorded point: record it, then honour a pause (lights to their safe state, wait) or an
        abort."""
        if not run.points:
            run.first_done = event.done - 1
            run.started_s = time.monotonic()
        run.points_done, run.points_total = event.done, event.total
        run.points.append({"sweep_id": event.sweep_id, "point_index": event.point_index, **event.latest})
        run.recoveries = {name: light.recoveries for name, light in rig.lights.items()}
        if rig.spectrometer is not None:
            run.recoveries["spectrometer"] = rig.spectrometer.recoveries
        camera = getattr(rig, "camera", None)
        if camera is not None:
            run.recoveries["camera_reconnects"] = camera.stats.reconnects
        self._changed()
        with run.cond:
            if run.want == "pause":
                paused_at = time.monotonic()
                run.lights_safe = self._lights_off(rig)
                run.state = "paused"
                self._changed()
                while run.want == "pause":
                    run.cond.wait()
                run.paused_for_s += time.monotonic() - paused_at
                run.lights_safe = None
            if run.want == "abort":
                raise RunAborted(run.id)
            if run.state != "running":  # resumed (the point's own change is told already)
                run.state = "running"
                self._changed()

    @staticmethod
    def _lights_off(rig) -> dict[str, bool]:
        """Every light of the rig switched off and read back (the sweep sets them again before the next point)."""
        reached = {}
        for name, light in rig.lights.items():
            try:
                light.set_output(False)
                reached[name] = light.output() is False
            except UwlabError:
                reached[name] = False
        return reached

    def command(self, run_id: str, action: str) -> Run:
        run = self.get(run_id)
        allowed = {"pause": ("running",), "resume": ("paused", "running"), "abort": ("running", "paused")}
        if run.state not in allowed[action] or (action == "resume" and run.want != "pause"):
            raise ConfigError("run", run_id, f"cannot {action} a {run.state} run")
        with run.cond:
            run.want = {"pause": "pause", "resume": "run", "abort": "abort"}[action]
            run.cond.notify_all()
        self._changed()
        return run

    def _changed(self) -> None:
        self.seq += 1
        self.live.changes.notify()

    def close(self) -> None:
        """Abort every run and wait for it to end (its rig to its safe state)."""
        for run in self.runs.values():
            with run.cond:
                run.want = "abort"
                run.cond.notify_all()
        deadline = time.monotonic() + 60
        while self.active() is not None and time.monotonic() < deadline:
            time.sleep(0.05)
