"""The rigs a sweep runs on: the tank (`HardwareRig`) and what the sweep engine needs of any rig (`Rig`).

`HardwareRig`: a camera by backend and id, the light and spectrometer on serial ports; whatever the rig cannot do
itself (set a manual aperture, move the spectrometer) is asked of the operator. The simulated rig
(`uwlab.experiments.acquisition.sim_rig.SimRig`, for ``uwlab sweep --sim``) follows the same `Rig` protocol; this
module never imports the simulator.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from uwlab.drivers.camera import Camera, open_camera
from uwlab.drivers.serial import Light, Spectrometer, open_light, open_spectrometer
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import Plan, SweepSpec
from uwlab.experiments.acquisition.roi import Rect, aruco_roi


class Rig(Protocol):
    """What the engine needs from a rig (`SimRig` or `HardwareRig`)."""

    sim: bool
    light: Light | None
    spectrometer: Spectrometer | None

    def open_camera(self, sweep: SweepSpec) -> Camera: ...
    def set_aperture(self, sweep: SweepSpec, f_number: float) -> None: ...
    def place_spectrometer(self, position: str) -> None: ...
    def board_roi(self, sweep: SweepSpec, camera: Camera, image: np.ndarray) -> Rect: ...
    def truth(self, camera: Camera) -> dict | None: ...


Confirm = Callable[[str], None]


class HardwareRig:
    """The tank: a camera by backend and id, the light and spectrometer on serial ports. ``confirm(message)``
    asks the operator to do something (set an aperture, move the spectrometer) and returns once done; None
    (``--non-interactive``) refuses every such request."""

    sim = False

    def __init__(self, plan: Plan, confirm: Confirm | None = None):
        self.plan = plan
        self.confirm = confirm
        self.light: Light | None = None
        self.spectrometer: Spectrometer | None = None
        self._position: str | None = None

    def __enter__(self) -> HardwareRig:
        ports = self.plan.instruments
        try:
            if ports.light_port is not None:
                self.light = open_light(ports.light_port, ports.protocol, reopen_s=ports.reopen_s)
            if ports.spectrometer_port is not None:
                self.spectrometer = open_spectrometer(ports.spectrometer_port, ports.protocol, reopen_s=ports.reopen_s)
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc_info) -> None:
        for device in (self.light, self.spectrometer):
            if device is not None:
                device.close()

    def open_camera(self, sweep: SweepSpec) -> Camera:
        return open_camera(sweep.camera.backend, sweep.camera.device_id, policy=sweep.camera.policy())

    def _ask(self, key: str, value: object, message: str) -> None:
        if self.confirm is None:
            raise ConfigError(key, value, f"needs the operator ({message}); refused under --non-interactive")
        self.confirm(message)

    def set_aperture(self, sweep: SweepSpec, f_number: float) -> None:
        self._ask(
            f"sweep.{sweep.id}.values", f_number, f"set the {sweep.lens.focal_length_mm:g} mm lens to F{f_number:g}"
        )

    def place_spectrometer(self, position: str) -> None:
        if position != self._position:
            self._ask("spectrometer", position, f"place the spectrometer at the {position}")
            self._position = position

    def board_roi(self, sweep: SweepSpec, camera: Camera, image: np.ndarray) -> Rect:
        return aruco_roi(image, sweep.aruco_dictionary)

    def truth(self, camera: Camera) -> dict | None:
        return None
