"""The simulated rig (`SimRig`), for ``uwlab sweep --sim``: the same code paths as the tank
(`uwlab.experiments.acquisition.rigs.HardwareRig`), with simulated devices, on the simulated tank or, for a rig
config with a ``[bench]`` table, the simulated EMVA 1288 bench (`uwlab.sim.bench`: a bare
sensor under a diffuse disk source, the spectrometer at the sensor plane).

- Light and spectrometer: the serial simulators (`uwlab.sim.devices.serial_sim.SerialRig`) in their own
  processes behind real pseudo-terminals, driven through the real serial drivers;
- camera: the in-process simulated camera through the real `Camera` interface, one per sweep, with the
  sweep's sensor profile and lens (`uwlab.sim.scene.RigScene` renders the electron-rate map);
- all of them share one `RigState` file, so a light level set through the serial driver dims the images;
- a plan's [[lights]] on pyvisa-sim (``visa_library = "PATH.yaml@sim"``) are driven through their instrument
  definitions on the third-party simulator; the first of them (`MirroredLight`) also passes its read-back (output,
  level) to the serial light, so it lights the simulated tank as the serial light would. Lights on real resources
  are replaced by the serial light (the first) or left out.

Apertures are set directly (`RigScene.set_lens` and a re-render); so are a geometry sweep's lens focus and target
distance: each geometry point renders a slanted-edge chart at the sensor's centre on the board
(`uwlab.sim.edge_chart.chart_rate_map`: defocus traced through the tank's wall, diffraction, the target's motion at
the rig's ``operation.speed_m_s`` over the exposure, the pixel) into the electron-rate map. Other sweeps render no
chart (their images are as before). The spectrometer is moved between the target and the camera with the
simulator's ``SIM:POS`` command. Every configuration is the scene's rendering (`RigScene.electron_rate_map`), a
colour sensor's each Bayer site through its own channel's QE; "no lens" gives a uniform field (per channel: a bare
sensor sees the whole hemisphere; see `uwlab.model.optics`). The simulated board carries no printed markers, so an
``aruco`` ROI is the board's footprint from the scene (what the detector would report).
The spectrometer simulator models the rig file's geometry; per-sweep geometry overrides change the images only.

The rig's temporary folder (``uwlab-simrig-*`` in the system's temporary directory: pseudo-terminal links, the
rig state) is removed when the rig closes. A process killed outright (SIGKILL) cannot; the next `SimRig` removes
such stale folders (`remove_stale_rig_folders`): each holds an owner lock (`uwlab.lockfile`) that a dead owner no
longer holds. Live rigs' folders are never touched.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from uwlab.drivers.camera import Camera, Settings, open_camera
from uwlab.drivers.camera.pixels import pixel_format
from uwlab.drivers.instruments import VisaLight, open_visa_light
from uwlab.drivers.serial import Light, Spectrometer, open_light, open_spectrometer
from uwlab.drivers.serial.ascii import AsciiSpectrometer
from uwlab.experiments.acquisition.plan import LightSpec, SweepSpec
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import Point
from uwlab.experiments.acquisition.rigs import GeometrySetting, to_safe_state
from uwlab.experiments.acquisition.roi import Rect
from uwlab.experiments.saturation import sensor_clip_dn
from uwlab.lockfile import OwnerLock, is_stale, read_holder
from uwlab.model.chain import beam_half_angle_rad
from uwlab.sim.bench import BenchScene
from uwlab.sim.devices.camera import SimFaults, SimSensor, SimTruth
from uwlab.sim.devices.serial_sim import SerialRig, SerialSimSettings
from uwlab.sim.edge_chart import chart_rate_map, rig_optics
from uwlab.sim.rig_state import RigState
from uwlab.sim.scene import RigScene, load_scene

RIG_FOLDER_PREFIX = "uwlab-simrig-"
OWNER_LOCK = "owner.lock"
UNOWNED_STALE_S = 600.0
SIM_REOPEN_S = 30.0  # a restarted simulator is a new Python process: slower to come back than a USB adapter


class SimRig:
    """The simulated rig (a context manager: simulators are always stopped, the temporary folder removed).

    ``seed`` seeds all of its noise: the cameras' (the rig's ``[sim] seed`` + ``seed``: fixed patterns and temporal
    noise) and the spectrometer's (``seed``); the light has none. Equal seeds give equal measurements.
    """

    sim = True

    def __init__(
        self, rig_path: Path, faults: SimFaults | None = None, seed: int = 0, lights: tuple[LightSpec, ...] = ()
    ):
        self.rig_path = Path(rig_path)
        self.light_specs = lights
        self.faults = faults
        self.seed = seed
        remove_stale_rig_folders()
        self._tmp = tempfile.TemporaryDirectory(prefix=RIG_FOLDER_PREFIX)
        self._owner = OwnerLock(Path(self._tmp.name) / OWNER_LOCK, "simulated rig")
        self._owner.acquire()
        self._serial = SerialRig(self._tmp.name, SerialSimSettings.from_config(self.rig_path), seed=seed)
        self.light: Light | None = None
        self.lights: dict[str, Light] = {}
        self.hold_levels: dict[str, float] = {spec.name: spec.level for spec in lights}
        self.safe_states: dict[str, bool] = {}
        self.spectrometer: Spectrometer | None = None
        self._scene: RigScene | BenchScene | None = None
        self._sensor: SimSensor | None = None
        self._sweep: SweepSpec | None = None
        self.camera: Camera | None = None

    def __enter__(self) -> SimRig:
        try:
            self._serial.start()
            self.lights = self._open_lights(open_light(self._serial.ports["light"], reopen_s=SIM_REOPEN_S))
            self.light = next(iter(self.lights.values()))
            self.spectrometer = open_spectrometer(self._serial.ports["spectrometer"], reopen_s=SIM_REOPEN_S)
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def _open_lights(self, serial_light: Light) -> dict[str, Light]:
        """The serial light as ``light`` (no [[lights]]), or the plan's lights: those on pyvisa-sim through their
        definitions (the first mirrored into the tank), the first otherwise replaced by the serial light."""
        if not self.light_specs:
            return {"light": serial_light}
        lights: dict[str, Light] = {}
        try:
            for index, spec in enumerate(self.light_specs):
                simulated = spec.visa_library is not None and spec.visa_library.endswith("@sim")
                if simulated:
                    visa = open_visa_light(spec.instrument, spec.resource, spec.visa_library, spec.max_current_a)
                    lights[spec.name] = MirroredLight(visa, serial_light) if index == 0 else visa
                elif index == 0:
                    lights[spec.name] = serial_light
        except BaseException:
            to_safe_state(lights)
            raise
        if not any(light is serial_light or isinstance(light, MirroredLight) for light in lights.values()):
            serial_light.close()
        return lights

    def close(self) -> None:
        if not self.safe_states:  # once: a released serial light would otherwise reopen its port to switch off
            self.safe_states = to_safe_state(self.lights)
        if self.spectrometer is not None:
            self.spectrometer.close()
        self._serial.stop()
        self._tmp.cleanup()
        self._owner.release()

    @property
    def rig_state_path(self) -> Path:
        return self._serial.rig_state_path

    @property
    def serial_rig(self) -> SerialRig:
        """The serial simulators (fault campaigns kill and restart them and read their true-state logs)."""
        return self._serial

    def open_camera(self, sweep: SweepSpec) -> Camera:
        """The sweep's simulated camera: its sensor profile and lens, lit by the shared light state (kept as
        ``camera`` while the sweep runs, for fault campaigns)."""
        scene = load_scene(self.rig_path, RigState(self.rig_state_path))
        scene.use(sweep.design, sweep.lens.bare)
        truth = SimTruth.from_sensor_profile(scene.sensor, **scene.sensor_realism())
        self._scene, self._sweep = scene, sweep
        self._sensor = SimSensor(truth, scene.electron_rate_map, scene.flux_fraction, seed=scene.sim.seed + self.seed)
        self.camera = open_camera("sim", "sim0", policy=sweep.camera.policy(), sensor=self._sensor, faults=self.faults)
        return self.camera

    def _open(self) -> tuple[RigScene | BenchScene, SimSensor, SweepSpec]:
        """The scene, simulated sensor and sweep of the camera `open_camera` opened last."""
        if self._scene is None or self._sensor is None or self._sweep is None:
            raise RuntimeError("no sweep's camera is open on the simulated rig")
        return self._scene, self._sensor, self._sweep

    def set_aperture(self, sweep: SweepSpec, f_number: float) -> None:
        """Set the simulated lens's f-number directly and re-render the scene."""
        scene, sensor, _ = self._open()
        scene.set_lens(f_number=f_number)
        sensor.set_rate_map(scene.electron_rate_map)

    def set_geometry(self, sweep: SweepSpec, point: Point) -> GeometrySetting:
        """Set the lens focus and the target's distance directly: the scene is rendered with the point's chart
        (module docstring); the chart's noise is seeded by the rig's seed and the point's index."""
        scene, sensor, _ = self._open()
        if not isinstance(scene, RigScene) or point.lens_focus_m is None or point.target_distance_m is None:
            raise ConfigError(f"sweep.{sweep.table.id}.kind", "geometry", "the simulated rig has no target here")
        try:
            optics = rig_optics(scene.design, scene.world, scene.tank is not None, float(scene.design["lens.f_number"]))
        except ValueError as exc:
            raise ConfigError(f"sweep.{sweep.table.id}.kind", "geometry", str(exc)) from None
        plain = scene.electron_rate_map
        focus, distance = point.lens_focus_m, point.target_distance_m
        speed = float(scene.design["operation.speed_m_s"])  # the sweep's design, on the scene
        seed = (scene.sim.seed + self.seed, point.index)

        def charted(shape: tuple[int, int]) -> np.ndarray:
            return chart_rate_map(
                plain(shape), optics, distance, focus, seed, speed_m_s=speed, exposure_s=point.exposure_us * 1e-6
            )

        sensor.set_rate_map(charted)
        return GeometrySetting(focus, distance, "rig")

    def place_spectrometer(self, position: str) -> None:
        """Move the simulated spectrometer (the simulator's ``SIM:POS`` command on its serial line)."""
        if not isinstance(self.spectrometer, AsciiSpectrometer):
            raise RuntimeError("the simulated rig's spectrometer is not open")
        self.spectrometer.transport.command(f"SIM:POS {position}")

    def board_roi(self, sweep: SweepSpec, camera: Camera, image: np.ndarray) -> Rect:
        """The board's footprint within the acquired window (the simulated board has no printed markers)."""
        scene, sensor, _ = self._open()
        width, height = sensor.truth.resolution_px
        bx, by, bw, bh = scene.board_roi((height, width))
        s = camera.read_settings()
        x0, y0 = max(bx - s.offset_x, 0), max(by - s.offset_y, 0)
        x1, y1 = min(bx + bw - s.offset_x, image.shape[1]), min(by + bh - s.offset_y, image.shape[0])
        return x0, y0, max(x1 - x0, 0), max(y1 - y0, 0)

    def truth(self, camera: Camera) -> dict:
        """Ground truth of the sweep's simulated sensor and light, for checking an EMVA characterisation."""
        scene, sensor, _ = self._open()
        truth = sensor.truth
        s = camera.read_settings()
        fmt_bits = pixel_format(s.pixel_format).bits
        common = {
            **{k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(truth).items()},
            "output_bit_depth": fmt_bits,
            "dn_scale": 2.0 ** (fmt_bits - truth.bit_depth),
            "K_dn_per_e_output": truth.system_gain(s.gain_db or 0.0) * 2.0 ** (fmt_bits - truth.bit_depth),
            "black_level_dn": s.black_level,
            "clip_level_dn": sensor_clip_dn(
                truth.system_gain(s.gain_db or 0.0),
                truth.saturation_e,
                truth.dark_offset_dn + (s.black_level or 0.0),
                truth.bit_depth,
                s.pixel_format,
            ),
            "light_gamma": scene.sim.light_gamma,
            "light_curve": "flux_fraction = level ** light_gamma",
            "window_mean_rate_e_per_s": float(self._window_rate(s).mean()),
        }
        if isinstance(scene, BenchScene):
            return {**common, **scene.truth()}
        return {
            **common,
            "on_axis_rate_e_per_s": scene.on_axis_rate_e_per_s(),
            "f_number": scene.design["lens.f_number"],
            "light_efficiency": scene.sim.light_efficiency,
            "attenuation_scale": float(scene.design["water.attenuation_scale"]),
            "beam_half_angle_deg": float(np.degrees(beam_half_angle_rad(scene.design))),
            "reflectance": float(scene.design["target.reflectance"]),
            "lens_transmittance": float(scene.design["lens.transmittance"]),
            "world": scene.world.summary(),
        }

    def _window_rate(self, s: Settings) -> np.ndarray:
        _, sensor, _ = self._open()
        rate = sensor.rate_e_per_s
        bh, bv = s.binning
        return rate[s.offset_y * bv : (s.offset_y + s.height) * bv, s.offset_x * bh : (s.offset_x + s.width) * bh]


class MirroredLight(Light):
    """A VISA light on pyvisa-sim that lights the simulated tank: after every set, its read-back (output, level) is
    set on the serial simulator's light, whose state the simulated camera and spectrometer see. Everything else
    (identity, read-backs, limits, drive and measured current, the safe state) is the VISA light's."""

    def __init__(self, visa: VisaLight, scene_light: Light) -> None:
        self.visa, self.scene_light = visa, scene_light
        self.port = visa.port

    @property
    def recoveries(self) -> int:
        return self.visa.recoveries + self.scene_light.recoveries

    @property
    def level_tolerance(self) -> float:
        return self.visa.level_tolerance

    @property
    def safe_state_reached(self) -> bool | None:
        return self.visa.safe_state_reached

    def identity(self) -> str:
        return self.visa.identity()

    def reset(self) -> None:
        self.visa.reset()
        self.scene_light.reset()

    def close(self) -> None:
        try:
            self.visa.close()
        finally:
            try:
                self.scene_light.set_output(False)
            finally:
                self.scene_light.close()

    def set_output(self, on: bool) -> None:
        self.visa.set_output(on)
        self.scene_light.set_output(self.visa.output())

    def output(self) -> bool:
        return self.visa.output()

    def set_level(self, level: float) -> None:
        self.visa.set_level(level)
        self.scene_light.set_level(min(max(self.visa.level(), 0.0), 1.0))

    def level(self) -> float:
        return self.visa.level()

    def state(self) -> dict:
        return self.visa.state()


def remove_stale_rig_folders(directory: str | os.PathLike | None = None) -> list[Path]:
    """Remove this user's simulated-rig folders in ``directory`` (default: the system's temporary directory) whose
    owner died without removing them: their owner lock is stale (`uwlab.lockfile.is_stale`), or, when it names no
    owner (an older uwlab, or a kill between creating the folder and locking it), they are older than
    `UNOWNED_STALE_S`.
    Returns the folders removed."""
    removed = []
    for folder in sorted(Path(directory or tempfile.gettempdir()).glob(f"{RIG_FOLDER_PREFIX}*")):
        try:
            info = folder.lstat()
        except OSError:
            continue
        if not folder.is_dir() or folder.is_symlink() or info.st_uid != os.getuid():
            continue
        lock = folder / OWNER_LOCK
        if read_holder(lock) is not None:
            stale = is_stale(lock)
        else:
            stale = time.time() - info.st_mtime > UNOWNED_STALE_S
        if stale:
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed
