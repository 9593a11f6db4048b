"""The sweep engine: measure every point of a plan, appending each to the dataset as it completes.

Per point (EMVA Standard 1288, Release 4.0 Linear, section 6 "Methods for computing the parameters"):
L ≥ 2 frames over the ROI give ``mean_dn`` (mean over all frames and pixels), ``temporal_var_dn2`` (for
frame pairs (0,1), (2,3), …: half the variance of the difference image, ``σ² = var(y_A − y_B) / 2``, the
standard's 1/(2NM)·Σ(y_A − y_B)² − (μ_A − μ_B)²/2, averaged over pairs) and ``spatial_var_dn2`` (sample
variance over the ROI of the L-frame mean image, *not* corrected for its residual temporal variance σ²/L).
The same statistics of dark frames (light off) at the point — or once per sweep ("block") — give the dark
columns and ``signal_dn = mean_dn − dark_mean_dn``. Frames are streamed through
`uwlab.experiments.frames.stack` (one frame in memory at a time). ``saturated_fraction`` is the fraction of ROI
pixels at the camera's clip level in any frame and the point is flagged ``saturated`` (never dropped), both by the
one rule of `uwlab.experiments.saturation`; the row is built by `uwlab.experiments.dataset.point_row`.

A camera delivering a raw Bayer format gives the same statistics per colour channel from the same frames, each
over its own sites of the ROI (``red_*``, ``green_*``, ``blue_*`` columns; EMVA 1288 Release 4.0 Linear §1.2: each
colour channel is a sensor of its own), and the row records the layout (``bayer``). A plan's ``camera.bayer``
declares the layout the camera must deliver: every remaining sweep's camera is checked before the first point is
measured, and a mismatch is refused (`ConfigError`, nothing recorded).

A geometry sweep (``kind = "geometry"``) also sets the point's lens focus and target distance (`Rig.set_geometry`:
directly on the simulated rig, by the operator on the tank, the values given recorded) and measures the slanted
edge on the mean of the point's lit frames (ISO 12233 e-SFR, `uwlab.experiments.frames.esfr.measure_edge`: in the
sweep's ``edge_roi``, else where one is found; per colour channel for a raw Bayer format), recorded next to the
radiometry (`uwlab.experiments.dataset.EDGE_FIELDS`); an edge that does not measure stops the sweep (`ConfigError`
naming the point).

With ``save_frames``, every frame the point was computed from, bright and dark (a shared dark block linked into
each point), is kept as TIFF with its settings (`uwlab.experiments.dataset_frames`), committed with the point.

Read-backs (`uwlab.experiments.acquisition.readbacks`): a point's lit frames and spectrometer readings are one
verified window — every light's output and level (the swept light at the point's level, the plan's other [[lights]]
at their hold level) and the camera's settings are read back before and after it, and
no instrument reset or reopen and no camera reconnect may happen within it; otherwise the point is measured
again (at most 3 times, then one `DeviceError`; the frames of a void attempt are not kept). Dark frames and the
spectrometer's dark references are verified windows of their own, with the light read back off. Each row records
the read-backs it used (``light_on_readback``, ``light_level_readback``, the swept light's drive and measured
current where its instrument has them: ``light_current_a_readback``, ``light_measured_current_a``; every light's
read-back as JSON: ``lights_readback``; ``exposure_us_readback``,
``gain_db_readback``, ``spectrometer_integration_ms_readback``, ``spectrometer_averaging_readback``), the window
(``readback_t_start_ns``, ``readback_t_end_ns``) and ``attempts``.

Resume (`open_for_resume`): the dataset's lock is taken, it must pass its check
(`uwlab.experiments.acquisition.dataset_check`) and come from the same plan; points already in it are skipped.
Every point is durable before the next starts, so Ctrl-C or a crash loses at most the point in progress. A device that
disappears is reconnected by its driver (settings restored and verified) and the point in progress is measured
again; a failed write raises `DatasetWriteError` with the dataset intact.
"""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from uwlab.drivers.camera import Camera, Frame, Settings
from uwlab.drivers.camera.pixels import pixel_format
from uwlab.drivers.serial.base import AVERAGING_RANGE, LightReadback, Spectrometer, SpectrometerReadback
from uwlab.errors import ConfigError
from uwlab.experiments.dataset import Dataset, FrameRecorder, point_row, spectra_frame, utc_now
from uwlab.experiments.acquisition.dataset_check import check
from uwlab.experiments.acquisition.light_calibration import measure_unsaturated
from uwlab.experiments.acquisition.plan import Plan, Point, SweepSpec, resolved_rig, sweep_tables
from uwlab.experiments.acquisition.readbacks import verified
from uwlab.experiments.acquisition.rigs import GeometrySetting, Rig
from uwlab.experiments.acquisition.roi import Rect, check_inside
from uwlab.experiments.acquisition.spectra import irradiance_w_m2
from uwlab.experiments.frames.esfr import EdgeMTF, measure_edge
from uwlab.experiments.frames.stack import StackAccumulator, StackStatistics
from uwlab.experiments.saturation import ClipLevel, frame_clip_level
from uwlab.provenance import provenance

DARK_AVERAGING = 16


@dataclass(frozen=True)
class Progress:
    """Reported after each recorded point: counts over the whole plan and the latest reading."""

    done: int
    total: int
    sweep_id: str
    point_index: int
    latest: dict


@dataclass(frozen=True)
class Reading:
    """One spectrometer reading at ``position`` and the settings it reads back right after it."""

    position: str
    wavelength_nm: np.ndarray
    irradiance_w_m2_nm: np.ndarray
    readback: SpectrometerReadback


@dataclass(frozen=True)
class FrameRecord:
    """What a point's row keeps of each frame it was computed from (its image is not kept)."""

    frame_id: int
    settings: Settings
    bayer: str | None


def _crop(image: np.ndarray, roi: Rect) -> np.ndarray:
    x, y, w, h = roi
    return image[y : y + h, x : x + w]


class SweepRunner:
    """Runs the points of a plan missing from ``dataset`` on ``rig``."""

    def __init__(
        self,
        plan: Plan,
        dataset: Dataset,
        rig: Rig,
        progress: Callable[[Progress], None] | None = None,
        sleep: Callable[[float], None] = time.sleep,
    ):
        self.plan = plan
        self.dataset = dataset
        self.rig = rig
        self.progress = progress
        self.sleep = sleep
        self._done = len(dataset.completed())
        self._spectrometer_darks: dict = {}
        self._swept: str | None = None  # the light the current sweep dims (the others hold their level)
        self._geometry: GeometrySetting | None = None  # a geometry point's focus and distance as set
        self._mean_image: np.ndarray | None = None  # the mean of a geometry point's lit frames

    def run(self) -> None:
        """Check every remaining sweep's colour filter layout, measure every remaining point, then record the
        finish time."""
        completed = self.dataset.completed()
        remaining = [
            (sweep, todo)
            for sweep in self.plan.sweeps
            if (todo := [p for p in sweep.points() if (sweep.table.id, p.index) not in completed])
        ]
        for sweep, _ in remaining:
            if (bayer := sweep.camera.bayer) is not None:
                with self.rig.open_camera(sweep) as camera:
                    self._check_layout(camera, sweep, bayer)
        for sweep, todo in remaining:
            self._run_sweep(sweep, todo)
        self.dataset.finish()

    def _check_layout(self, camera: Camera, sweep: SweepSpec, bayer: str) -> None:
        """Refuse (`ConfigError` on ``camera.bayer``, or the sweep's own ``camera.bayer``) a camera whose pixel
        format does not deliver the layout ``bayer`` the plan declares."""
        spec = sweep.camera
        if spec.pixel_format is not None:
            camera.pixel_format = spec.pixel_format
        try:
            camera.check_bayer(bayer)
        except ConfigError as exc:
            key = f"sweep.{sweep.table.id}.camera.bayer" if "bayer" in self._sweep_camera(sweep) else "camera.bayer"
            raise ConfigError(key, exc.value, exc.reason) from None

    def _sweep_camera(self, sweep: SweepSpec) -> dict:
        """The keys a sweep's own ``camera`` table sets (over [camera])."""
        return sweep_tables(self.plan.raw).get(sweep.table.id, {}).get("camera", {})

    def _run_sweep(self, sweep: SweepSpec, todo: list[Point]) -> None:
        self._needs_instruments(sweep)
        table = sweep.table
        self._swept = table.light or next(iter(self.rig.lights), None)
        block_frames = None
        with self.rig.open_camera(sweep) as camera:
            self._configure(camera, sweep)
            self._record_devices(sweep, camera)
            self._set_light(table.kind != "dark", table.light_level, table.settle_s)
            roi = self._roi(sweep, camera)
            try:
                block = None
                if table.dark == "block":
                    block_frames = self.dataset.dark_block_recorder(table.id) if table.save_frames else None
                    block = self._dark(sweep, camera, roi, block_frames)
                for point in todo:
                    self._record(sweep, camera, roi, point, block, block_frames)
            finally:
                if block_frames is not None:
                    block_frames.discard()

    def _record(
        self,
        sweep: SweepSpec,
        camera: Camera,
        roi: Rect,
        point: Point,
        block: StackStatistics | None,
        block_frames: FrameRecorder | None,
    ) -> None:
        """Measure one point and record it (with its frames when the sweep saves them)."""
        frames = self.dataset.frame_recorder(sweep.table.id, point.index) if sweep.table.save_frames else None
        try:
            row, spectra = self._measure(sweep, camera, roi, point, block, frames)
            if frames is not None and block_frames is not None:
                frames.link_darks(block_frames)
            self.dataset.append_point(row, spectra, frames)
        finally:
            if frames is not None:
                frames.discard()  # nothing left once committed; an interrupted point's frames otherwise
        self._done += 1
        if self.progress is not None:
            self.progress(
                Progress(
                    self._done,
                    self.plan.total_points(),
                    sweep.table.id,
                    point.index,
                    {k: row[k] for k in ("exposure_us", "signal_dn", "saturated")},
                )
            )

    def _needs_instruments(self, sweep: SweepSpec) -> None:
        table = sweep.table
        if not self.rig.lights and (table.kind in ("light-level", "dark") or table.dark != "none"):
            raise ConfigError("lights", None, f"sweep {table.id} switches or dims the light: the plan needs [[lights]]")
        if table.light is not None and table.light not in self.rig.lights:
            raise ConfigError(
                f"sweep.{table.id}.light", table.light, f"not on this rig (its lights: {', '.join(self.rig.lights)})"
            )
        if table.spectrometer:
            self._spectrometer(sweep)  # refused now, before anything is measured

    def _configure(self, camera: Camera, sweep: SweepSpec) -> None:
        spec = sweep.camera
        if spec.pixel_format is not None:
            camera.pixel_format = spec.pixel_format
        if spec.bayer is not None:
            self._check_layout(camera, sweep, spec.bayer)
        if spec.window is not None:
            camera.set_roi(*spec.window)
        if sweep.table.black_level_dn is not None:
            camera.black_level = sweep.table.black_level_dn
        camera.gain_db = sweep.table.gain_db
        camera.exposure_us = sweep.exposure_us
        if self.rig.spectrometer is not None and sweep.table.spectrometer:
            self.rig.spectrometer.set_integration_ms(sweep.table.spectrometer_integration_ms)
            self.rig.spectrometer.set_averaging(sweep.table.spectrometer_averaging)

    def _record_devices(self, sweep: SweepSpec, camera: Camera) -> None:
        info = camera.info
        devices = {
            "camera": {
                "vendor": info.vendor,
                "model": info.model,
                "serial": info.serial,
                "firmware": info.firmware,
                "backend": info.backend,
                "id": info.device_id,
            },
            "light": self.rig.lights[self._swept].identity() if self._swept is not None else None,
            "lights": {name: light.identity() for name, light in self.rig.lights.items()},
            "light_placements": {
                spec.name: {
                    "placement": spec.placement,
                    "position_m": sweep.rig_raw["lights"][spec.placement]["position_m"],
                }
                for spec in self.plan.lights
                if spec.placement is not None
            },
            "spectrometer": self.rig.spectrometer.identity() if self.rig.spectrometer is not None else None,
        }
        changes = {"devices": {sweep.table.id: devices}, "rigs": {sweep.table.id: resolved_rig(sweep.design)}}
        truth = self.rig.truth(camera)
        if truth is not None:
            changes["sim_truth"] = {sweep.table.id: truth}
        self.dataset.update_metadata(**changes)

    def _set_light(self, on: bool, level: float, settle_s: float) -> None:
        """The swept light to ``level``, every other light to its hold level, all of them ``on`` (or off)."""
        if not self.rig.lights:
            return
        for name, want in self._wanted_light(on, level).items():
            light = self.rig.lights[name]
            light.set_level(want.level)
            light.set_output(want.on)
        self.sleep(settle_s)

    def _wanted_light(self, on: bool, level: float) -> dict[str, LightReadback]:
        """The state wanted of each light: the swept one at ``level``, the others at their hold level."""
        return {
            name: LightReadback(on, level if name == self._swept else self.rig.hold_levels.get(name, level))
            for name in self.rig.lights
        }

    def _roi(self, sweep: SweepSpec, camera: Camera) -> Rect:
        image = camera.acquire(1)[0].image
        height, width = image.shape
        if sweep.table.roi is None:
            return 0, 0, width, height
        if sweep.table.roi == "aruco":
            return check_inside(f"sweep.{sweep.table.id}.roi", self.rig.board_roi(sweep, camera, image), image.shape)
        return check_inside(f"sweep.{sweep.table.id}.roi", sweep.table.roi, image.shape)

    def _dark(
        self,
        sweep: SweepSpec,
        camera: Camera,
        roi: Rect,
        recorder: FrameRecorder | None = None,
        point: Point | None = None,
    ) -> StackStatistics:
        """Statistics of dark frames (light read back off before and after), leaving the light as the sweep
        wants it; with a ``recorder``, the frames of the recorded attempt are kept."""
        level = sweep.table.light_level

        def stack() -> StackStatistics:
            if recorder is not None:
                recorder.forget("dark")
            return self._stack(
                sweep, camera, roi, sweep.dark_frames, self._keeper(recorder, "dark", sweep, camera, roi, point)
            )[0]

        stats, _ = verified(
            f"sweep {sweep.table.id}: dark frames",
            self.rig,
            camera,
            self._wanted_light(False, level),
            lambda: self._set_light(False, level, sweep.table.settle_s),
            stack,
            self._swept,
        )
        self._set_light(sweep.table.kind != "dark", level, 0.0)
        return stats

    def _stack(
        self, sweep: SweepSpec, camera: Camera, roi: Rect, count: int, keep: Callable[[Frame], None] | None = None
    ) -> tuple[StackStatistics, ClipLevel, list[FrameRecord]]:
        """Streaming statistics of ``count`` frames over the ROI (one frame in memory at a time), the clip level
        (from the sweep's sensor profile and the first frame, `uwlab.experiments.saturation`) and the frames'
        records (`FrameRecord`: no images); ``keep`` (saving raw frames) sees every frame. A raw Bayer frame's
        channels are accumulated too, each over its own sites of the ROI (`uwlab.experiments.frames.stack`)."""
        accumulator: StackAccumulator | None = None
        clip: ClipLevel | None = None
        kept: list[FrameRecord] = []
        for frame in camera.frames(count):
            image = _crop(frame.image, roi)
            if accumulator is None:
                clip = frame_clip_level(frame, sweep.design.sensor, image)
                accumulator = StackAccumulator(clip.dn, bayer=frame.bayer, origin=(roi[0], roi[1]))
            accumulator.add(image)
            if keep is not None:
                keep(frame)
            kept.append(FrameRecord(frame.frame_id, frame.settings, frame.bayer))
        if accumulator is None or clip is None:
            raise ValueError(f"no frames to stack (count {count})")
        return accumulator.result(), clip, kept

    def _apply(self, sweep: SweepSpec, camera: Camera, point: Point) -> None:
        """Every setting the point depends on: camera exposure and gain, aperture, light output and level."""
        camera.exposure_us = point.exposure_us
        camera.gain_db = point.gain_db
        if sweep.table.kind == "aperture" or sweep.table.step == "f_number":
            if point.f_number is None:  # an aperture sweep's points carry their own (`SweepSpec.points`)
                raise ValueError(f"sweep {sweep.table.id} point {point.index}: no f-number to set")
            self.rig.set_aperture(sweep, point.f_number)
        if sweep.table.kind == "geometry":
            self._geometry = self.rig.set_geometry(sweep, point)
        self._set_light(point.light_on, point.light_level, 0.0)
        self.sleep(sweep.table.settle_s)

    def _lit(
        self, sweep: SweepSpec, camera: Camera, roi: Rect, point: Point, recorder: FrameRecorder | None
    ) -> tuple[StackStatistics, ClipLevel, list[FrameRecord], list[Reading]]:
        """The point's own frames and spectrometer readings (the verified window); a geometry point's frames are
        also summed for its edge (`_edges`)."""
        if recorder is not None:
            recorder.forget("bright")
        keep = self._keeper(recorder, "bright", sweep, camera, roi, point)
        total: list[np.ndarray] = []
        if sweep.table.kind == "geometry":
            keeper = keep

            def keep(frame: Frame) -> None:
                if keeper is not None:
                    keeper(frame)
                if total:
                    total[0] += frame.image
                else:
                    total.append(frame.image.astype(np.float64))

        bright, clip, frames = self._stack(sweep, camera, roi, sweep.table.frames_per_point, keep)
        self._mean_image = total[0] / len(frames) if total else None
        return bright, clip, frames, [self._reading(sweep, position) for position in sweep.table.spectrometer]

    def _edges(self, sweep: SweepSpec, point: Point, clip: ClipLevel, bayer: str | None) -> dict | None:
        """A geometry point's e-SFR on the mean of its lit frames (None for other points); `ConfigError` naming the
        point when its edge does not measure."""
        if sweep.table.kind != "geometry" or self._mean_image is None:
            return None
        try:
            edges: dict[str | None, EdgeMTF] = measure_edge(self._mean_image, sweep.table.edge_roi, bayer, clip.dn)
        except ConfigError as exc:
            raise ConfigError(
                f"sweep.{sweep.table.id}.edge_roi", exc.value, f"point {point.index}: {exc.reason}"
            ) from None
        return edges

    def _measure(
        self,
        sweep: SweepSpec,
        camera: Camera,
        roi: Rect,
        point: Point,
        block: StackStatistics | None,
        recorder: FrameRecorder | None,
    ) -> tuple[dict, pd.DataFrame]:
        t_start = time.time_ns()
        (bright, clip, frames, raw), window = verified(
            f"sweep {sweep.table.id} point {point.index}",
            self.rig,
            camera,
            self._wanted_light(point.light_on, point.light_level),
            lambda: self._apply(sweep, camera, point),
            lambda: self._lit(sweep, camera, roi, point, recorder),
            self._swept,
        )
        for reading in reversed(raw):  # the spectrometer is at the last position: measure its darks first
            self._spectrometer_dark(sweep, reading.position, reading.readback.integration_ms)
        readings = [self._minus_dark(sweep, reading) for reading in raw]
        dark = block
        if sweep.table.dark == "point":
            dark = self._dark(sweep, camera, roi, recorder, point)
        settings = frames[-1].settings
        edges = self._edges(sweep, point, clip, frames[-1].bayer)
        geometry = self._geometry if edges is not None else None
        lens = replace(sweep.lens, f_number=point.f_number)
        swept_state = window.lights.get(self._swept, {}) if self._swept is not None else {}
        row = point_row(
            sweep_id=sweep.table.id,
            point_index=point.index,
            kind=sweep.table.kind,
            bright=bright,
            dark=dark,
            clip=clip,
            saturation_threshold=sweep.table.saturation_threshold,
            edges=edges,
            lens_focus_m=geometry.lens_focus_m if geometry else None,
            target_distance_m=geometry.target_distance_m if geometry else None,
            geometry_set_by=geometry.set_by if geometry else None,
            bayer=frames[-1].bayer,
            camera_backend=camera.info.backend,
            camera_id=camera.info.device_id,
            camera_model=camera.info.model,
            sensor_profile=sweep.sensor_profile,
            lens_label=lens.label,
            focal_length_mm=lens.focal_length_mm,
            f_number=point.f_number,
            exposure_us=point.exposure_us,
            gain_db=point.gain_db,
            black_level_dn=settings.black_level,
            light_level=point.light_level if self._swept is not None else None,
            light_on=point.light_on,
            bit_depth=pixel_format(settings.pixel_format).bits,
            roi_x=roi[0],
            roi_y=roi[1],
            roi_w=roi[2],
            roi_h=roi[3],
            exposure_us_readback=settings.exposure_us,
            gain_db_readback=settings.gain_db,
            light_on_readback=window.light.on if window.light else None,
            light_level_readback=window.light.level if window.light else None,
            light_current_a_readback=swept_state.get("current_a"),
            light_measured_current_a=swept_state.get("measured_current_a"),
            lights_readback=json.dumps(window.lights, sort_keys=True) if window.lights else None,
            spectrometer_integration_ms_readback=raw[0].readback.integration_ms if raw else None,
            spectrometer_averaging_readback=raw[0].readback.averaging if raw else None,
            readback_t_start_ns=window.t_start_ns,
            readback_t_end_ns=window.t_end_ns,
            attempts=window.attempts,
            temperature_c=camera.temperature_c,
            irradiance_w_m2=irradiance_w_m2(readings[0][1], readings[0][2]) if readings else None,
            irradiance_position=readings[0][0] if readings else None,
            frame_ids=[f.frame_id for f in frames],
            t_start_ns=t_start,
            t_end_ns=time.time_ns(),
        )
        return row, spectra_frame(sweep.table.id, point.index, readings)

    def _spectrometer(self, sweep: SweepSpec) -> Spectrometer:
        """The rig's spectrometer, which the sweep reads (`ConfigError` when the rig has none)."""
        if self.rig.spectrometer is None:
            raise ConfigError("instruments.spectrometer_port", None, f"sweep {sweep.table.id} reads the spectrometer")
        return self.rig.spectrometer

    def _reading(self, sweep: SweepSpec, position: str) -> Reading:
        """A spectrometer reading at ``position`` (integration halved while it saturates) and its read-back."""
        spectrometer = self._spectrometer(sweep)
        self.rig.place_spectrometer(position)
        wavelength_nm, irradiance = measure_unsaturated(spectrometer)
        return Reading(position, wavelength_nm, irradiance, spectrometer.readback())

    def _minus_dark(self, sweep: SweepSpec, reading: Reading) -> tuple[str, np.ndarray, np.ndarray]:
        """The reading minus the spectrometer's own light-off reading (see `_spectrometer_dark`)."""
        dark_nm, dark = self._spectrometer_dark(sweep, reading.position, reading.readback.integration_ms)
        return (
            reading.position,
            reading.wavelength_nm,
            reading.irradiance_w_m2_nm - np.interp(reading.wavelength_nm, dark_nm, dark),
        )

    def _spectrometer_dark(
        self, sweep: SweepSpec, position: str, integration_ms: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """What the spectrometer reports with the light off at ``integration_ms`` (its imperfectly subtracted
        dark signal), measured once per sweep, position and integration time in a verified window (light read
        back off). It is read with DARK_AVERAGING times the usual averaging (up to the instrument's limit): every
        reading of the sweep shares its noise, which would otherwise bias the sweep's whole flux scale. The
        spectrometer's integration time and averaging are left as they were."""
        spectrometer = self._spectrometer(sweep)
        key = (sweep.table.id, position, integration_ms)
        if key not in self._spectrometer_darks:
            was = spectrometer.readback()

            def prepare() -> None:
                self._set_light(False, sweep.table.light_level, sweep.table.settle_s)
                self.rig.place_spectrometer(position)
                spectrometer.set_integration_ms(integration_ms)
                spectrometer.set_averaging(min(AVERAGING_RANGE[1], DARK_AVERAGING * was.averaging))

            try:
                self._spectrometer_darks[key], _ = verified(
                    f"sweep {sweep.table.id}: spectrometer dark at the {position}",
                    self.rig,
                    None,
                    self._wanted_light(False, sweep.table.light_level),
                    prepare,
                    spectrometer.read_spectrum,
                    self._swept,
                )
            finally:
                spectrometer.set_integration_ms(was.integration_ms)
                spectrometer.set_averaging(was.averaging)
            self._set_light(sweep.table.kind != "dark", sweep.table.light_level, sweep.table.settle_s)
        return self._spectrometer_darks[key]

    def _keeper(
        self,
        recorder: FrameRecorder | None,
        role: str,
        sweep: SweepSpec,
        camera: Camera,
        roi: Rect,
        point: Point | None = None,
    ) -> Callable[[Frame], None] | None:
        """What writes each ``role`` frame to ``recorder`` with its settings (None without a recorder)."""
        if recorder is None:
            return None
        context = {
            "sweep_id": sweep.table.id,
            "point_index": None if point is None else point.index,
            "light_on": role == "bright" and sweep.table.kind != "dark",
            "light_level": sweep.table.light_level if point is None else point.light_level,
            "f_number": sweep.lens.f_number if point is None else point.f_number,
            "roi": list(roi),
            "camera": asdict(camera.info),
        }

        def keep(frame: Frame) -> None:
            recorder.add(
                role,
                frame.image,
                {
                    "frame_id": frame.frame_id,
                    "timestamp_ns": frame.timestamp_ns,
                    "pixel_format": frame.pixel_format,
                    "settings": frame.settings.to_dict(),
                    **context,
                },
            )

        return keep


def open_for_resume(root: str | Path, plan: Plan, sim: bool, purpose: str = "resuming a sweep") -> Dataset:
    """The dataset at ``root`` open for writing, to complete with ``plan``: its lock taken (refused while another
    writer holds it), recorded from the same plan on the same kind of rig (`check_resumable`), passing its check
    (`uwlab.experiments.acquisition.dataset_check.check`; a damaged one is refused, naming the repair), the leftovers of
    interrupted writes removed and its finish time cleared. The session that resumes is added to ``resumed`` (its
    time, host and `uwlab.provenance.provenance`): ``provenance`` stays the one that started the dataset, so a
    sweep completed on another machine or with other versions says so."""
    dataset = Dataset.open_for_writing(root, purpose)
    try:
        check_resumable(dataset, plan, sim)
        report = check(dataset)
        if not report.ok:
            raise ConfigError(
                "resume",
                str(root),
                f"the dataset fails its check: {report.summary_line()}; "
                f"`uwlab dataset check {root}` lists the problems, `--repair` "
                "sets the damaged points aside (kept in quarantine/) so that "
                "--resume measures them again",
            )
        dataset.remove_strays()
        session = {"utc": utc_now(), "host": socket.gethostname(), "provenance": provenance()}
        dataset.update_metadata(finished_utc=None, resumed=[*dataset.metadata.get("resumed", []), session])
    except BaseException:
        dataset.close()
        raise
    return dataset


def check_resumable(dataset: Dataset, plan: Plan, sim: bool) -> None:
    """Refuse to resume a dataset recorded from another plan (or on another kind of rig), with the reason."""
    if dataset.plan_sha256 != plan.sha256:
        raise ConfigError(
            "resume",
            str(dataset.root),
            f"recorded with a different plan (plan_sha256 {dataset.plan_sha256[:12]}…, "
            f"{plan.path} has {plan.sha256[:12]}…)",
        )
    if bool(dataset.metadata.get("sim")) != sim:
        was = "the simulated rig" if dataset.metadata.get("sim") else "hardware"
        raise ConfigError("resume", str(dataset.root), f"recorded on {was}; resume it the same way")
