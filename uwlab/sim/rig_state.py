"""Shared state of the simulated rig: what the simulated light is doing right now.

The simulated light (a serial simulator in its own process) writes this state; the simulated
camera and spectrometer read it, so dimming the light dims the images. The state lives in a
small JSON file replaced atomically (``os.replace``), which any process can read without locks.
Without a file, the state is held in memory (a single-process rig).

Warm-up drift: an LED's output falls as its junction heats (e.g. Narendran & Gu, "Life of LED-based white light
sources", J. Display Technology 1(1), 167–171, 2005). The light's heat h ∈ [0, 1] (0 cold, 1 settled) is written
by the light with its state; the emitted flux is flux_fraction · (1 + A (1 − h)): a cold light gives 1 + A times
its settled output. The heat follows the light's use, not the wall clock, so that equal seeds give equal
measurements (`uwlab.sim.devices.serial_instruments.SimLight`).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

from uwlab.model.data import read_json


@dataclass(frozen=True)
class LightState:
    """Light output: ``on`` and the commanded ``level`` in [0, 1]; ``flux_fraction`` is the
    emitted fraction of the rated luminous flux after the light's level→flux curve."""

    on: bool = True
    level: float = 1.0
    flux_fraction: float = 1.0
    heat: float = 1.0
    drift_amplitude: float = 0.0

    @property
    def effective_fraction(self) -> float:
        """Emitted flux / rated flux: 0 when off, else flux_fraction × the warm-up factor 1 + A (1 − h)."""
        if not self.on:
            return 0.0
        return self.flux_fraction * (1.0 + self.drift_amplitude * (1.0 - self.heat))


class RigState:
    """Light state shared between simulated instruments, optionally through a file."""

    def __init__(self, path: str | os.PathLike | None = None, initial: LightState | None = None):
        self.path = Path(path) if path is not None else None
        self._light = initial or LightState()
        if self.path is not None and (initial is not None or not self.path.exists()):
            self._write(self._light)

    @property
    def light(self) -> LightState:
        if self.path is None:
            return self._light
        try:
            return LightState(**read_json(self.path, "--rig-state"))
        except (OSError, ValueError, TypeError):  # ConfigError is a ValueError: a file not (yet) readable
            return self._light

    def set_light(self, state: LightState) -> None:
        self._light = state
        if self.path is not None:
            self._write(state)

    def _write(self, state: LightState) -> None:
        assert self.path is not None  # only a file-backed state is written
        fd, tmp = tempfile.mkstemp(dir=self.path.parent, prefix=".rig-state-")
        with os.fdopen(fd, "w") as fh:
            json.dump(asdict(state), fh)
        os.replace(tmp, self.path)


@dataclass(frozen=True)
class WarmUp:
    """The light's warm-up drift (`LightState`): a cold light emits 1 + ``amplitude`` times its
    settled output; each time it is switched on its heat h moves towards settled as if it ran for a nominal use,
    h ← 1 − (1 − h) e^(−1/``switch_ons``), so it settles (1 − 1/e) in ``switch_ons`` uses. Tied to use rather
    than the wall clock, the drift is the same in every run of a campaign."""

    amplitude: float = 0.0
    switch_ons: float = 20.0

    def warmer(self, heat: float) -> float:
        return 1.0 - (1.0 - heat) * math.exp(-1.0 / self.switch_ons)
