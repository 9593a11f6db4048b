"""Verified measurements: a sweep records a point only if the devices provably held its settings throughout.

A measurement (a point's lit frames and spectra, a stack of dark frames, a spectrometer dark reference) runs in
a *window* bracketed by read-backs (docs/sweeps.md, "What a point guarantees"):

1. ``prepare()`` applies the settings (camera, aperture, lights), then the read-backs are checked: every light's
   output and level against the values wanted (within the light's own ``level_tolerance``: a VISA light's drive
   reads back to the definition's tolerance, absolute and relative), a CV/CC supply's delivery (its ``delivery``
   read-back: in CC, the measured current within tolerance of the set one, not a short), the camera's settings
   read from the device against those it
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
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

from uwlab.drivers.camera import Camera
from uwlab.drivers.serial import Light, Spectrometer
from uwlab.drivers.serial.base import LightReadback
from uwlab.errors import DeviceError

ATTEMPTS = 3
LEVEL_TOLERANCE = 1e-9
T = TypeVar("T")


class RigInstruments(Protocol):
    lights: dict[str, Light]
    spectrometer: Spectrometer | None


@dataclass(frozen=True)
class Window:
    """A verified measurement: when it ran (wall clock, ns), at which attempt, the read-back that held of the
    primary light (``light``: the one the sweep dims) and of every light (``lights``: name → `light_state`)."""

    t_start_ns: int
    t_end_ns: int
    attempts: int
    light: LightReadback | None
    lights: dict[str, dict[str, Any]] = field(default_factory=dict)


def light_state(light: Light) -> dict[str, Any]:
    """What a light reads back now: ``on``, ``level`` and, where its driver has them (a VISA light), the drive
    (e.g. ``current_a``) and the measured drive (e.g. ``measured_current_a``)."""
    state = getattr(light, "state", None)
    if callable(state):
        return dict(state())
    readback = light.readback()
    return {"on": readback.on, "level": readback.level}


def _marks(rig: RigInstruments, camera: Camera | None) -> dict[str, int]:
    marks = {} if camera is None else {"camera reconnects": camera.stats.reconnects}
    for name, device in (*rig.lights.items(), ("spectrometer", rig.spectrometer)):
        if device is not None:
            marks[f"{name} resets/reopens"] = device.recoveries
    return marks


def _readbacks(
    rig: RigInstruments, camera: Camera | None, wanted: dict[str, LightReadback]
) -> tuple[dict[str, dict[str, Any]], list[str]]:
    """Every wanted light's read-back and where it disagrees; the camera's settings verified (if it takes part)."""
    states, problems = {}, []
    for name, want in wanted.items():
        light = rig.lights[name]
        got = states[name] = light_state(light)
        tolerance = getattr(light, "level_tolerance", LEVEL_TOLERANCE)
        if got["on"] != want.on or abs(got["level"] - want.level) > tolerance:
            problems.append(
                f"{name} reads back on={got['on']} level={got['level']:g}, want on={want.on} level={want.level:g}"
            )
        elif got.get("delivery", "ok") not in ("ok", "off", "unchecked"):  # a supply not delivering in CC
            problems.append(f"{name}: {got['delivery']}")
    if camera is not None:
        camera.verify_settings()
    return states, problems


def verified(
    what: str,
    rig: RigInstruments,
    camera: Camera | None,
    wanted: dict[str, LightReadback],
    prepare: Callable[[], None],
    measure: Callable[[], T],
    primary: str | None = None,
) -> tuple[T, Window]:
    """``measure()``'s result and its `Window`, from the first attempt whose read-backs held (module docstring);
    ``camera`` is the camera the measurement uses (None: a spectrometer-only measurement, which a camera outage
    does not void); ``wanted`` the state wanted of each light by name (empty: the rig has no light); ``primary``
    the light whose read-back is the window's ``light``."""
    problems: list[str] = []
    for attempt in range(1, ATTEMPTS + 1):
        prepare()
        _, problems = _readbacks(rig, camera, wanted)
        if problems:
            continue
        before = _marks(rig, camera)
        t_start = time.time_ns()
        result = measure()
        t_end = time.time_ns()
        states, problems = _readbacks(rig, camera, wanted)
        after = _marks(rig, camera)
        problems += [
            f"{name} {before[name]} -> {after[name]} during the measurement"
            for name in before
            if after[name] != before[name]
        ]
        if not problems:
            main = states.get(primary) if primary is not None else None
            light = LightReadback(main["on"], main["level"]) if main is not None else None
            return result, Window(t_start, t_end, attempt, light, states)
    raise DeviceError(
        f"{what}: read-backs disagree after {ATTEMPTS} attempts ({'; '.join(problems)}); nothing of it was recorded"
    )
