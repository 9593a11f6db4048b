"""Verified measurements: a sweep records a point only if the devices provably held its settings throughout.

A measurement (a point's lit frames and spectra, a stack of dark frames, a spectrometer dark reference) runs in
a *window* bracketed by read-backs (docs/sweeps.md, "What a point guarantees"):

1. ``prepare()`` applies the settings (camera, aperture, light), then the read-backs are checked: the light's
   output and level against the values wanted, the camera's settings read from the device against those it
   reported when they were set (`Camera.verify_settings`: a camera whose settings changed behind our back is
   reconnected and its settings restored and verified, which counts as a reconnect);
2. the recovery counters are noted: each serial instrument's `recoveries` (resets and reopens after which its
   driver restored its settings) and the camera's `stats.reconnects`;
3. ``measure()`` runs, between the window's wall-clock start and end;
4. the same read-backs are checked again, and the counters must not have moved: an instrument that reset or
   restarted, or a camera that was reconnected, during the window may have delivered data in its power-on state.

Any disagreement makes the attempt void; the window is measured again from step 1, at most `ATTEMPTS` times,
then the sweep stops with one `DeviceError` naming what disagreed. Nothing of a void attempt is recorded.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TypeVar

from uwlab.drivers.camera import Camera
from uwlab.drivers.serial import Light, Spectrometer
from uwlab.drivers.serial.base import LightReadback
from uwlab.errors import DeviceError

ATTEMPTS = 3
LEVEL_TOLERANCE = 1e-9
T = TypeVar("T")


class Instruments(Protocol):
    light: Light | None
    spectrometer: Spectrometer | None


@dataclass(frozen=True)
class Window:
    """A verified measurement: when it ran (wall clock, ns), at which attempt, the light read-back that held."""

    t_start_ns: int
    t_end_ns: int
    attempts: int
    light: LightReadback | None


def _marks(rig: Instruments, camera: Camera | None) -> dict[str, int]:
    marks = {} if camera is None else {"camera reconnects": camera.stats.reconnects}
    for name, device in (("light", rig.light), ("spectrometer", rig.spectrometer)):
        if device is not None:
            marks[f"{name} resets/reopens"] = device.recoveries
    return marks


def _readbacks(
    rig: Instruments, camera: Camera | None, light: LightReadback | None
) -> tuple[LightReadback | None, list[str]]:
    """The light's read-back and whether it disagrees with ``light``; the camera's settings verified (if it takes
    part)."""
    got = rig.light.readback() if rig.light is not None else None
    problems = []
    if light is not None and got is not None and (got.on != light.on or abs(got.level - light.level) > LEVEL_TOLERANCE):
        problems.append(f"light reads back on={got.on} level={got.level:g}, want on={light.on} level={light.level:g}")
    if camera is not None:
        camera.verify_settings()
    return got, problems


def verified(
    what: str,
    rig: Instruments,
    camera: Camera | None,
    light: LightReadback | None,
    prepare: Callable[[], None],
    measure: Callable[[], T],
) -> tuple[T, Window]:
    """``measure()``'s result and its `Window`, from the first attempt whose read-backs held (module docstring);
    ``camera`` is the camera the measurement uses (None: a spectrometer-only measurement, which a camera outage
    does not void); ``light`` is the light state wanted (None: the rig has no light)."""
    problems: list[str] = []
    for attempt in range(1, ATTEMPTS + 1):
        prepare()
        _, problems = _readbacks(rig, camera, light)
        if problems:
            continue
        before = _marks(rig, camera)
        t_start = time.time_ns()
        result = measure()
        t_end = time.time_ns()
        light_after, problems = _readbacks(rig, camera, light)
        after = _marks(rig, camera)
        problems += [
            f"{name} {before[name]} -> {after[name]} during the measurement"
            for name in before
            if after[name] != before[name]
        ]
        if not problems:
            return result, Window(t_start, t_end, attempt, light_after)
    raise DeviceError(
        f"{what}: read-backs disagree after {ATTEMPTS} attempts ({'; '.join(problems)}); nothing of it was recorded"
    )
