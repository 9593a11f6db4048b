"""The rigs a sweep runs on: the tank (`HardwareRig`) and what the sweep engine needs of any rig (`Rig`).

`HardwareRig`: a camera by backend and id, the plan's [[lights]] by instrument definition on their VISA resources
(or the deprecated ``uwlab-ascii`` light on a serial port), the spectrometer; whatever the rig cannot do itself
(set a manual aperture, move the spectrometer) is asked of the operator. The simulated rig
(`uwlab.experiments.acquisition.sim_rig.SimRig`, for ``uwlab sweep --sim``) follows the same `Rig` protocol; this
module never imports the simulator.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from uwlab.drivers.camera import Camera, open_camera
from uwlab.drivers.ocean_insight import open_instrument
from uwlab.drivers.serial import Light, Spectrometer, open_light, open_spectrometer
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import Plan, Point, SweepSpec
from uwlab.experiments.acquisition.roi import Rect, aruco_roi
from uwlab.model.data import resolve_path


class Rig(Protocol):
    """What the engine needs from a rig (`SimRig` or `HardwareRig`). ``lights``: every light by name (``light`` is
    the first, None without lights); ``hold_levels``: the level each holds while a sweep dims another;
    ``safe_states``: after the rig closed, whether each light read back in its safe state (output off)."""

    sim: bool
    light: Light | None
    lights: dict[str, Light]
    hold_levels: dict[str, float]
    safe_states: dict[str, bool]
    spectrometer: Spectrometer | None

    def open_camera(self, sweep: SweepSpec) -> Camera: ...
    def set_aperture(self, sweep: SweepSpec, f_number: float) -> None: ...
    def place_spectrometer(self, position: str) -> None: ...
    def set_geometry(self, sweep: SweepSpec, point: Point) -> GeometrySetting: ...
    def board_roi(self, sweep: SweepSpec, camera: Camera, image: np.ndarray) -> Rect: ...
    def truth(self, camera: Camera) -> dict | None: ...


Confirm = Callable[[str], None]
# Asks the operator to set something by hand (the message) and returns the value set, given the one requested.
AskValue = Callable[[str, float], float]


@dataclass(frozen=True)
class GeometrySetting:
    """A geometry point's lens focus setting and target distance as they were set, and by whom: ``"rig"`` (set
    directly: the simulated rig) or ``"operator"`` (by hand, the values given at the prompt)."""

    lens_focus_m: float
    target_distance_m: float
    set_by: str


def to_safe_state(lights: dict[str, Light]) -> dict[str, bool]:
    """Switch every light off (its safe state), read each back and release it, whatever fails on the way:
    ``{name: True}`` where the output read back off. A light whose driver switches itself off on close
    (`uwlab.drivers.instruments.VisaLight`) reports what it read back then."""
    reached: dict[str, bool] = {}
    for name, light in lights.items():
        try:
            light.set_output(False)
            reached[name] = light.output() is False
        except Exception:
            reached[name] = False
        finally:
            try:
                light.close()
            except Exception:
                reached[name] = False
        after_close = getattr(light, "safe_state_reached", None)
        if after_close is not None:
            reached[name] = reached[name] and bool(after_close)
    return reached


def open_plan_lights(plan: Plan) -> dict[str, Light]:
    """The plan's [[lights]] opened by instrument definition (``max_current_a`` the rig's maximum drive,
    ``forward_voltage_v`` and ``identity_contains`` as the rig gives them); any that fails closes those already open
    (each goes to its safe state)."""
    from uwlab.drivers.instruments import open_light_instrument

    lights: dict[str, Light] = {}
    try:
        for spec in plan.lights:
            lights[spec.name] = open_light_instrument(
                spec.instrument,
                spec.resource,
                spec.visa_library,
                spec.max_current_a,
                spec.forward_voltage_v,
                spec.identity_contains,
            )
    except BaseException:
        to_safe_state(lights)
        raise
    return lights


class HardwareRig:
    """The tank: a camera by backend and id, the light and spectrometer on serial ports. ``confirm(message)``
    asks the operator to do something (set an aperture, move the spectrometer) and returns once done; ``ask_value``
    asks for a setting made by hand (the lens focus ring, the target's distance: the tank has no motorised axis) and
    returns the value set; None (``--non-interactive``) refuses every such request."""

    sim = False

    def __init__(self, plan: Plan, confirm: Confirm | None = None, ask_value: AskValue | None = None):
        self.plan = plan
        self.confirm = confirm
        self.ask_value = ask_value
        self._geometry: dict[str, tuple[float, float]] = {}  # setting → (requested, given) last
        self.light: Light | None = None
        self.lights: dict[str, Light] = {}
        self.hold_levels: dict[str, float] = {spec.name: spec.level for spec in plan.lights}
        self.safe_states: dict[str, bool] = {}
        self.spectrometer: Spectrometer | None = None
        self._position: str | None = None

    def __enter__(self) -> HardwareRig:
        ports = self.plan.instruments
        try:
            if ports.light_port is not None:
                self.lights = {"light": open_light(ports.light_port, ports.protocol, reopen_s=ports.reopen_s)}
            else:
                self.lights = open_plan_lights(self.plan)
            self.light = next(iter(self.lights.values()), None)
            if ports.spectrometer_port is not None:
                self.spectrometer = open_spectrometer(ports.spectrometer_port, ports.protocol, reopen_s=ports.reopen_s)
            if (usb := ports.seabreeze_spectrometer) is not None:  # dark: electric where it can, else the sweep's
                self.spectrometer = open_instrument(
                    usb.instrument,
                    usb.resource,
                    resolve_path(usb.calibration, self.plan.path.parent),
                    usb.area_cm2,
                    dark_mode="auto",
                )
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc_info) -> None:
        if not self.safe_states:  # once: a released serial light would otherwise reopen its port to switch off
            self.safe_states = to_safe_state(self.lights)
        if self.spectrometer is not None:
            self.spectrometer.close()

    def open_camera(self, sweep: SweepSpec) -> Camera:
        return open_camera(sweep.camera.backend, sweep.camera.device_id, policy=sweep.camera.policy())

    def _ask(self, key: str, value: object, message: str) -> None:
        if self.confirm is None:
            raise ConfigError(key, value, f"needs the operator ({message}); refused under --non-interactive")
        self.confirm(message)

    def set_aperture(self, sweep: SweepSpec, f_number: float) -> None:
        self._ask(
            f"sweep.{sweep.table.id}.values",
            f_number,
            f"set the {sweep.lens.focal_length_mm:g} mm lens to F{f_number:g}",
        )

    def place_spectrometer(self, position: str) -> None:
        if position != self._position:
            self._ask("spectrometer", position, f"place the spectrometer at the {position}")
            self._position = position

    def set_geometry(self, sweep: SweepSpec, point: Point) -> GeometrySetting:
        """The operator sets the focus ring and places the target by hand, asked only when the requested value
        changes; the values they give are recorded."""
        focus = self._given(
            sweep, "lens_focus_m", point.lens_focus_m, "set the lens focus to {:.4g} m (air-equivalent)"
        )
        distance = self._given(
            sweep, "target_distance_m", point.target_distance_m, "place the target {:.4g} m from the lens's pupil"
        )
        return GeometrySetting(focus, distance, "operator")

    def _given(self, sweep: SweepSpec, setting: str, requested: float | None, message: str) -> float:
        if requested is None:
            raise ValueError(f"sweep {sweep.table.id}: a geometry point without {setting}")
        last = self._geometry.get(setting)
        if last is not None and last[0] == requested:
            return last[1]
        if self.ask_value is None:
            raise ConfigError(
                f"sweep.{sweep.table.id}.{setting}",
                requested,
                f"needs the operator ({message.format(requested)}); refused under --non-interactive",
            )
        given = float(self.ask_value(message.format(requested), requested))
        self._geometry[setting] = (requested, given)
        return given

    def board_roi(self, sweep: SweepSpec, camera: Camera, image: np.ndarray) -> Rect:
        return aruco_roi(image, sweep.table.aruco_dictionary)

    def truth(self, camera: Camera) -> dict | None:
        return None
