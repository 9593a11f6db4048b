"""Fault campaigns on the simulated rig: break devices at random moments of a sweep, then compare what the sweep
recorded with what the simulators really did.

`FaultInjector` runs in a thread beside a sweep and, at seeded random moments, performs one of the faults it was
given (`serial_restart`: a serial simulator killed and restarted on its port; `camera_outage`: the in-process
simulated camera unreachable for a while, coming back power-cycled; a campaign script may add its own, e.g. a GigE
Vision server killed or frozen). `wrong_points` checks every recorded point against the serial simulators'
true-state logs (`uwlab.sim.state_log`), which the sweep never reads: over the point's verified window
(``readback_t_start_ns`` … ``readback_t_end_ns``) the light must have held the recorded output and level without
interruption, and the spectrometer must have taken the recorded reading with the recorded settings in that light.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from uwlab.drivers.camera import Camera
from uwlab.sim.devices.camera import SimTransport
from uwlab.sim.devices.serial_sim import SerialRig
from uwlab.sim.state_log import reads_during, states_during

LEVEL_TOLERANCE = 1e-9
Fault = Callable[[np.random.Generator], "dict | None"]


def serial_restart(serial: SerialRig, name: str, down_s: tuple[float, float] = (0.0, 0.5)) -> Fault:
    """A fault that cuts the power of simulator ``name`` and restarts it after a random pause in ``down_s``."""

    def fault(rng: np.random.Generator) -> dict:
        pause = float(rng.uniform(*down_s))
        started = time.monotonic()
        serial.kill(name)
        time.sleep(pause)
        serial.restart(name)
        return {"fault": f"{name} restart", "down_s": time.monotonic() - started}

    return fault


def camera_outage(camera: Callable[[], Camera | None], outage_s: tuple[float, float]) -> Fault:
    """A fault that makes the simulated camera ``camera()`` (on a `SimTransport`; None: no camera open yet, nothing
    done) unreachable for a random time in ``outage_s``; it comes back power-cycled."""

    def fault(rng: np.random.Generator) -> dict | None:
        target = camera()
        if target is None:
            return None
        transport = target.transport
        if not isinstance(transport, SimTransport):
            raise TypeError(f"a camera outage needs a simulated camera, not {type(transport).__name__}")
        seconds = float(rng.uniform(*outage_s))
        transport.cut(seconds)
        time.sleep(seconds)
        return {"fault": "camera outage", "down_s": seconds}

    return fault


@dataclass
class FaultInjector:
    """Performs ``faults`` (picked at random) one after another, a random pause in ``every_s`` apart, until
    stopped or ``limit`` were done; ``trials`` lists what was done (a fault returning None did nothing). Use as a
    context manager around a sweep."""

    faults: list[Fault]
    seed: int
    every_s: tuple[float, float] = (0.5, 3.0)
    limit: int | None = None
    trials: list[dict] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(self.seed)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fault-injector", daemon=True)
        self.error: BaseException | None = None

    def _run(self) -> None:
        try:
            while self.limit is None or len(self.trials) < self.limit:
                if self._stop.wait(float(self._rng.uniform(*self.every_s))):
                    return
                fault = self.faults[int(self._rng.integers(len(self.faults)))]
                t_ns = time.time_ns()
                done = fault(self._rng)
                if done is not None:
                    self.trials.append({"t_ns": t_ns, **done})
        except BaseException as exc:  # reported by __exit__: a fault that could not be performed is a campaign error
            self.error = exc

    def __enter__(self) -> FaultInjector:
        self._thread.start()
        return self

    def __exit__(self, *exc_info) -> None:
        self._stop.set()
        self._thread.join()
        if self.error is not None and exc_info[0] is None:
            raise RuntimeError(f"fault injection failed: {self.error!r}") from self.error


def wrong_points(points: pd.DataFrame, light_log: list[dict], spectrometer_log: list[dict]) -> list[str]:
    """One line per recorded point that disagrees with the simulators' logs (module docstring); [] if none."""
    wrong = []
    for row in points.itertuples(index=False):
        where = f"{row.sweep_id}#{row.point_index}"
        t0, t1 = int(row.readback_t_start_ns), int(row.readback_t_end_ns)
        if light_log and row.light_level is not None and not pd.isna(row.light_level):
            level_error = abs(row.light_level_readback - row.light_level)
            if row.light_on_readback != row.light_on or level_error > LEVEL_TOLERANCE:
                wrong.append(
                    f"{where}: read-back {row.light_on_readback}/{row.light_level_readback} recorded for "
                    f"{row.light_on}/{row.light_level}"
                )
            for state in states_during(light_log, t0, t1):
                if (
                    state["event"] == "power-lost"
                    or state["on"] != row.light_on
                    or abs(state["level"] - row.light_level) > LEVEL_TOLERANCE
                ):
                    wrong.append(
                        f"{where}: recorded light {row.light_on}/{row.light_level}, the light was "
                        f"{state['event']} {state['on']}/{state['level']} at {state['t_ns']}"
                    )
        if row.irradiance_position is not None and not pd.isna(row.irradiance_w_m2):
            wrong += _spectrometer_disagreements(
                where, row, reads_during(spectrometer_log, t0, t1), states_during(spectrometer_log, t0, t1)[1:]
            )
    return wrong


def _spectrometer_disagreements(where: str, row, reads: list[dict], changes: list[dict]) -> list[str]:
    wrong = [
        f"{where}: spectrometer {c['event']} during the window"
        for c in changes
        if c["event"] in ("power-lost", "power-on")
    ]
    matching = [
        r
        for r in reads
        if r["position"] == row.irradiance_position
        and r["integration_ms"] == row.spectrometer_integration_ms_readback
        and r["averaging"] == row.spectrometer_averaging_readback
    ]
    if not matching:
        wrong.append(
            f"{where}: no reading at the {row.irradiance_position} with "
            f"{row.spectrometer_integration_ms_readback} ms x {row.spectrometer_averaging_readback} "
            f"in the window (reads: {[(r['position'], r['integration_ms'], r['averaging']) for r in reads]})"
        )
    for read in reads:
        if read["light_on"] != row.light_on or (
            row.light_level is not None and abs(read["light_level"] - row.light_level) > LEVEL_TOLERANCE
        ):
            wrong.append(
                f"{where}: spectrometer read in light {read['light_on']}/{read['light_level']}, recorded "
                f"{row.light_on}/{row.light_level}"
            )
    return wrong
