"""Grabbing frames from one camera with statistics per frame — what `uwlab grab` and `uwlab.grab` run.

Each frame's statistics are `uwlab.experiments.frames.frame.frame_statistics`: size, pixel format, the settings
read back with it, mean, standard deviation, minimum, maximum and the fraction of saturated pixels by the one rule
of `uwlab.experiments.saturation` (the clip level from the sensor profile when one is known, else from the pixel
format and the image), and the same per colour channel of a raw Bayer frame. Frames can be kept as TIFF files with
their settings in the metadata (`save_tiff`; never overwriting a file).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

from uwlab.drivers.camera import Camera, Frame, Policy, open_camera
from uwlab.errors import ConfigError
from uwlab.experiments.frames.frame import frame_statistics
from uwlab.model.schema import check, limits
from uwlab.model.sensor import SensorProfile, load_sensor_profile
from uwlab.outputs import output_dir

# Frames of one grab: 100 000 is ~20 min at 100 fps; a larger count is a typo, refused before the camera opens.
GrabFrames = Annotated[int, limits(1, 100_000, "frames", hint="", integer=True)]

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd


def parse_roi(text: str) -> tuple[int, int, int, int]:
    """``"x,y,w,h"`` → (x, y, w, h), offsets ≥ 0 and sizes ≥ 1.

    >>> parse_roi("0,8,64,32")
    (0, 8, 64, 32)
    """
    try:
        x, y, w, h = (int(v) for v in text.split(","))
    except ValueError:
        raise ConfigError("roi", text, "expected four integers x,y,w,h") from None
    if min(x, y) < 0 or min(w, h) < 1:
        raise ConfigError("roi", text, "offsets must be >= 0 and sizes >= 1")
    return x, y, w, h


@dataclass(frozen=True)
class Settings:
    """Camera settings to apply before grabbing (None: leave as the camera has it)."""

    exposure_us: float | None = None
    gain_db: float | None = None
    pixel_format: str | None = None
    roi: tuple[int, int, int, int] | None = None
    bayer: str | None = None  # the colour filter layout the camera must deliver (refused when it offers none)

    def check(self) -> None:
        """Plausibility limits (`uwlab.model.schema`) before anything is sent to a camera."""
        from uwlab.model.schema import ExposureUs, GainDb, check

        if self.exposure_us is not None:
            check(ExposureUs, self.exposure_us, "--exposure-us")
        if self.gain_db is not None:
            check(GainDb, self.gain_db, "--gain-db")

    def apply(self, cam: Camera) -> None:
        """Write the settings (the camera reads each back and refuses a value it did not take). With `bayer` and
        no `pixel_format`, the device's own format delivering that layout (`Camera.bayer_format`)."""
        chosen = self.pixel_format
        if not chosen and self.bayer is not None:
            chosen = cam.bayer_format(self.bayer)
        if chosen and chosen != cam.pixel_format:
            cam.pixel_format = chosen
        if self.roi:
            cam.set_roi(*self.roi)
        if self.exposure_us is not None:
            cam.exposure_us = self.exposure_us
        if self.gain_db is not None:
            cam.gain_db = self.gain_db
        if self.bayer is not None:
            cam.check_bayer(self.bayer)


@dataclass
class Grabbed:
    """What `grab_frames` returns: the device (its `CameraInfo` fields and ``discarded_frames``), the frames (when
    kept), a statistics row per frame and the TIFF files written.

    Examples
    --------
    See `uwlab.grab`.
    """

    device: dict[str, Any]
    frames: list[Frame] = field(default_factory=list, repr=False)
    rows: list[dict[str, Any]] = field(default_factory=list, repr=False)
    saved: list[Path] = field(default_factory=list, repr=False)

    @property
    def stats(self) -> pd.DataFrame:
        """One row per frame (the module's statistics)."""
        import pandas as pd

        return pd.DataFrame(self.rows)

    @property
    def images(self) -> list[np.ndarray]:
        """The kept frames' images in DN."""
        return [frame.image for frame in self.frames]


def unique_path(directory: Path, stem: str) -> Path:
    """A new file name in ``directory``: existing files are never overwritten."""
    candidate, n = directory / f"{stem}.tiff", 1
    while candidate.exists():
        candidate, n = directory / f"{stem}-{n}.tiff", n + 1
    return candidate


def save_tiff(directory: Path, frame: Frame, device: dict[str, Any]) -> Path:
    """Write ``frame`` as a TIFF with the device, frame id, timestamp, pixel format and read-back settings in its
    metadata; a new file name every time (created exclusively)."""
    import tifffile

    metadata = {
        "device": device,
        "frame_id": frame.frame_id,
        "timestamp_ns": frame.timestamp_ns,
        "pixel_format": frame.pixel_format,
        "settings": frame.settings.to_dict(),
    }
    while True:
        path = unique_path(directory, f"frame-{frame.frame_id:06d}")
        try:
            with open(path, "xb") as fh:
                tifffile.imwrite(fh, frame.image, metadata=metadata)
            return path
        except FileExistsError:
            continue


def sensor_for(backend: str, sensor: str | None, config: str | None) -> SensorProfile | None:
    """The sensor profile giving the clip level: `sensor` (a name or TOML), else for the simulated camera its
    rig's, else None (the clip level is then detected from the frames)."""
    if sensor is not None:
        return load_sensor_profile(sensor)
    if backend == "sim":
        from uwlab.sim.scene import RigScene

        return RigScene.from_toml(config).sensor
    return None


def chosen_backend(backend: str | None, fake: bool) -> str:
    """The camera backend a grab uses: `backend`, else the fake cameras' (Aravis, whose ``Fake_1`` is the default
    device there) when `fake`, else the simulated camera.

    >>> chosen_backend(None, False), chosen_backend(None, True), chosen_backend("harvesters", True)
    ('sim', 'aravis', 'harvesters')
    """
    if backend is not None:
        return backend
    return "aravis" if fake else "sim"


def grab_frames(
    backend: str | None = None,
    device_id: str | None = None,
    *,
    frames: int = 1,
    settings: Settings | None = None,
    sensor: str | None = None,
    config: str | None = None,
    cti: list[str] | None = None,
    fake: bool = False,
    timeout_s: float = 5.0,
    keep_frames: bool = True,
    save_dir: str | os.PathLike[str] | None = None,
) -> Grabbed:
    """Open the camera, apply `settings`, acquire `frames` frames and compute their statistics; the camera is
    closed on any exit. `backend` None: `chosen_backend`. `fake`: the backend's test camera
    (`uwlab.drivers.camera.open_camera`). `keep_frames` False keeps only the statistics (long grabs); `save_dir` (a
    folder, created if its parent exists: `uwlab.outputs.output_dir`) receives each frame as TIFF. Everything is
    checked before the camera opens."""
    backend = chosen_backend(backend, fake)
    frames = check(GrabFrames, frames, "frames")
    settings = settings or Settings()
    settings.check()
    folder = output_dir(save_dir, "--save") if save_dir is not None else None
    if folder is not None:
        folder.mkdir(exist_ok=True)
    options: dict[str, Any] = {"fake": fake}
    if backend == "harvesters":
        options["cti"] = list(cti or [])
    if backend == "sim":
        options["config"] = config
    profile = sensor_for(backend, sensor, config)
    with open_camera(backend, device_id, policy=Policy(timeout_s=timeout_s), **options) as cam:
        settings.apply(cam)
        result = Grabbed(device=dict(vars(cam.info)))
        for frame in cam.stream(frames):
            result.rows.append(frame_statistics(frame, profile))
            if keep_frames:
                result.frames.append(frame)
            if folder is not None:
                result.saved.append(save_tiff(folder, frame, result.device))
        result.device["discarded_frames"] = cam.stats.discarded
    return result
