"""Simulated ``uwlab-ascii`` instruments: command handlers of the light and the spectrometer.

Each handler maps one command line to its reply lines (docs/serial-protocol.md); the serving loop,
the pseudo-terminal and fault injection are in `uwlab.sim.devices.serial_sim`. With a `StateLog`, every
change of state (power-on, command) and every spectrometer reading is logged with the full state, so
tests can compare recorded data against what the instrument really did.

Light: output on/off and level x ∈ [0, 1]; the emitted fraction of the rated flux follows the
non-linear curve ``flux_fraction = x ** gamma`` (a gamma-law dimmer; gamma from the rig config key
``[sim] light_gamma``), times its warm-up factor (`uwlab.sim.rig_state`; amplitude and time constant
from the rig's ``[world]``, none in the ideal world). Every change is written to the shared `RigState`, so the
simulated camera and spectrometer see it. Power-on / reset state: output off, level 0, cold.

Spectrometer: reports the spectral irradiance ``spectrum(position, flux_fraction)`` [W/m²/nm] of the
rig model for the current light state, resampled to 380–780 nm in 1 nm steps, through a CCD-like
count model per pixel and frame (e.g. Janesick, *Photon Transfer*, SPIE 2007):
``counts = bias + k·t·E + dark_rate·t + N(0, √(k·t·E + dark_rate·t)) + N(0, read_noise)``, clipped to
[0, full_scale] (saturation). Frames are averaged; the instrument then subtracts its stored dark
reference, which is off by ``dark_error`` (a relative error), and divides by ``k·t``. Integration time
1–10000 ms, averaging 1–100; an acquisition takes integration × averaging of real time. ``SIM:BLOCK ON`` puts
something between the light and the spectrometer (a capped fibre, a light aimed elsewhere): it then reads the dark
whatever the light does, until ``SIM:BLOCK OFF``; a reset of the instrument does not move it.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from uwlab.drivers.serial.base import AVERAGING_RANGE, INTEGRATION_MS_RANGE
from uwlab.drivers.serial.protocol import (
    BLOCK_BEGIN,
    BLOCK_END,
    ERR_BAD_ARGUMENT,
    ERR_OUT_OF_RANGE,
    ERR_UNKNOWN_COMMAND,
    ERROR_CODES,
    format_float,
)
from uwlab.sim.rig_state import LightState, RigState, WarmUp
from uwlab.sim.state_log import StateLog
from uwlab.model.evaluation import SPECTROMETER_POSITIONS
from uwlab.model.grid import DEFAULT_GRID

SpectrumSource = Callable[[str, float], tuple[np.ndarray, np.ndarray]]
ECHO_CHARS = 32


class CommandError(Exception):
    """A command the instrument refuses: becomes ``ERR <code> <message>``."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = code


def _quoted(text: str) -> str:
    """``text`` for an error message: quoted, at most `ECHO_CHARS` characters of it."""
    return repr(text[:ECHO_CHARS]) + ("..." if len(text) > ECHO_CHARS else "")


def _argument_in_range(argument: str, low: float, high: float) -> float:
    try:
        value = float(argument)
    except ValueError:
        raise CommandError(ERR_BAD_ARGUMENT, f"not a number: {_quoted(argument)}") from None
    if not low <= value <= high:
        raise CommandError(ERR_OUT_OF_RANGE, f"{_quoted(argument)} outside [{low:g}, {high:g}]")
    return value


def _integer(argument: str, low: int, high: int) -> int:
    if not re.fullmatch(r"[+-]?[0-9]{1,12}", argument):
        raise CommandError(ERR_BAD_ARGUMENT, f"not an integer: {_quoted(argument)}")
    return int(_argument_in_range(argument, low, high))


class SimInstrument:
    """Command dispatch shared by the simulated instruments: ``*IDN?``, ``*RST``, ``SYST:ERR?``."""

    model = "SIM"

    def __init__(self, serial_number: str = "0001", state_log: StateLog | None = None):
        self.identity = f"UWLAB,{self.model},{serial_number},1.0"
        self.state_log = state_log
        self._last_error = (0, "No error")
        self.power_on()

    @property
    def banner(self) -> str:
        return f"# {self.identity} ready"

    def power_on(self) -> None:
        """Go to the power-on state (at start, after ``*RST`` or a spontaneous reset) and log it."""
        self.set_power_on_state()
        self.record("power-on")

    def set_power_on_state(self) -> None:
        """Set the instrument's power-on state."""

    def state(self) -> dict:
        """The instrument's full state, as logged."""
        return {}

    def record(self, event: str, **extra: object) -> None:
        """Append ``event`` with the full state to the state log, if there is one."""
        if self.state_log is not None:
            self.state_log.append(event, **self.state(), **extra)

    def handle(self, line: str) -> list[str]:
        """Reply lines for one command line."""
        header, _, argument = line.strip().partition(" ")
        header = header.upper()
        try:
            if header == "*IDN?":
                return [self.identity]
            if header == "*RST":
                self.power_on()
                return [self.banner, "OK"]
            if header == "SYST:ERR?":
                code, message = self._last_error
                self._last_error = (0, "No error")
                return [f"{code} {message}"]
            return self.dispatch(header, argument.strip())
        except CommandError as exc:
            self._last_error = (exc.code, str(exc))
            return [f"ERR {exc.code} {exc}"]

    def dispatch(self, header: str, argument: str) -> list[str]:
        raise CommandError(ERR_UNKNOWN_COMMAND, f"{ERROR_CODES[ERR_UNKNOWN_COMMAND]} {_quoted(header)}")


class SimLight(SimInstrument):
    """Gamma-law dimmable light writing its state to the rig state."""

    model = "SIM-LIGHT"

    def __init__(
        self,
        rig_state: RigState,
        gamma: float = 2.2,
        serial_number: str = "0001",
        state_log: StateLog | None = None,
        drift: WarmUp | None = None,
    ):
        self.rig_state = rig_state
        self.gamma = gamma
        self.drift = drift or WarmUp()
        super().__init__(serial_number, state_log)

    def set_power_on_state(self) -> None:
        self.on = False
        self.level = 0.0
        self.light_state = LightState(False, 0.0, 0.0, heat=0.0, drift_amplitude=self.drift.amplitude)
        self._publish()

    def state(self) -> dict:
        return {"on": self.on, "level": self.level, "flux_fraction": self.level**self.gamma}

    def dispatch(self, header: str, argument: str) -> list[str]:
        if header == "OUTP" and argument.upper() in ("ON", "OFF", "1", "0"):
            self.on = argument.upper() in ("ON", "1")
        elif header == "OUTP":
            raise CommandError(ERR_BAD_ARGUMENT, f"expected ON or OFF, got {_quoted(argument)}")
        elif header == "OUTP?":
            return ["1" if self.on else "0"]
        elif header == "LEV":
            self.level = _argument_in_range(argument, 0.0, 1.0)
        elif header == "LEV?":
            return [format_float(self.level)]
        else:
            return super().dispatch(header, argument)
        self._publish()
        self.record("command")
        return ["OK"]

    def _publish(self) -> None:
        old = self.light_state
        heat = self.drift.warmer(old.heat) if self.on and not old.on else old.heat
        self.light_state = replace(old, on=self.on, level=self.level, flux_fraction=self.level**self.gamma, heat=heat)
        self.rig_state.set_light(self.light_state)


@dataclass(frozen=True)
class DetectorModel:
    """Count model of the simulated spectrometer (see the module docstring)."""

    counts_per_w_m2_nm_s: float = 1.0e6
    full_scale_counts: float = 65535.0
    bias_counts: float = 1000.0
    dark_rate_counts_s: float = 200.0
    read_noise_counts: float = 8.0
    dark_error: float = 0.02

    def dark_counts(self, integration_s: float) -> float:
        return self.bias_counts + self.dark_rate_counts_s * integration_s

    def expected_sigma_w_m2_nm(self, irradiance: np.ndarray, integration_s: float, averaging: int) -> np.ndarray:
        """Standard deviation of one reported value: shot, dark-current and read noise, averaged."""
        gain = self.counts_per_w_m2_nm_s * integration_s
        variance = gain * np.maximum(irradiance, 0) + self.dark_rate_counts_s * integration_s
        return np.sqrt((variance + self.read_noise_counts**2) / averaging) / gain

    def dark_residual_w_m2_nm(self, integration_s: float) -> float:
        """The offset left by the imperfect dark subtraction."""
        gain = self.counts_per_w_m2_nm_s * integration_s
        return self.dark_error * self.dark_counts(integration_s) / gain

    def measure(
        self, irradiance: np.ndarray, integration_s: float, averaging: int, rng: np.random.Generator
    ) -> tuple[np.ndarray, bool]:
        """Reported irradiance [W/m²/nm] and whether any pixel of any frame saturated."""
        gain = self.counts_per_w_m2_nm_s * integration_s
        signal = gain * np.maximum(irradiance, 0)
        dark = self.dark_counts(integration_s)
        shot = np.sqrt(signal + self.dark_rate_counts_s * integration_s)
        frames = dark + signal + rng.standard_normal((averaging, signal.size)) * np.hypot(shot, self.read_noise_counts)
        saturated = bool(np.any(frames >= self.full_scale_counts))
        counts = np.clip(frames, 0, self.full_scale_counts).mean(axis=0)
        return (counts - dark * (1 - self.dark_error)) / gain, saturated


class SimSpectrometer(SimInstrument):
    """Spectrometer at ``position`` reporting ``spectrum(position, flux_fraction)`` with detector noise."""

    model = "SIM-SPECTROMETER"

    def __init__(
        self,
        rig_state: RigState,
        spectrum: SpectrumSource,
        position: str = "target",
        detector: DetectorModel = DetectorModel(),
        seed: int | None = None,
        serial_number: str = "0001",
        state_log: StateLog | None = None,
    ):
        self.rig_state = rig_state
        self.spectrum = spectrum
        self.position = position
        self.detector = detector
        self.wavelength_nm = DEFAULT_GRID.nm
        self.rng = np.random.default_rng(seed)
        self.blocked = False
        super().__init__(serial_number, state_log)

    def set_power_on_state(self) -> None:
        self.integration_ms = 100.0
        self.averaging = 1

    def state(self) -> dict:
        return {
            "integration_ms": self.integration_ms,
            "averaging": self.averaging,
            "position": self.position,
            "blocked": self.blocked,
        }

    def dispatch(self, header: str, argument: str) -> list[str]:
        if header == "SPEC:INT":
            self.integration_ms = _argument_in_range(argument, *INTEGRATION_MS_RANGE)
        elif header == "SPEC:INT?":
            return [format_float(self.integration_ms)]
        elif header == "SPEC:AVG":
            self.averaging = _integer(argument, *AVERAGING_RANGE)
        elif header == "SPEC:AVG?":
            return [str(self.averaging)]
        elif header == "SPEC:READ?":
            return self.read()
        elif header == "SIM:POS" and argument.lower() in SPECTROMETER_POSITIONS:
            self.position = argument.lower()
        elif header == "SIM:POS":
            raise CommandError(ERR_BAD_ARGUMENT, f"position must be one of {', '.join(SPECTROMETER_POSITIONS)}")
        elif header == "SIM:POS?":
            return [self.position]
        elif header == "SIM:BLOCK" and argument.upper() in ("ON", "OFF"):
            self.blocked = argument.upper() == "ON"
        elif header == "SIM:BLOCK":
            raise CommandError(ERR_BAD_ARGUMENT, "expected SIM:BLOCK ON|OFF")
        elif header == "SIM:BLOCK?":
            return ["ON" if self.blocked else "OFF"]
        else:
            return super().dispatch(header, argument)
        self.record("command")
        return ["OK"]

    def true_irradiance(self, flux_fraction: float) -> np.ndarray:
        """The model's spectral irradiance at the light's ``flux_fraction``, on the instrument's grid."""
        wavelength_nm, irradiance = self.spectrum(self.position, flux_fraction)
        return np.interp(self.wavelength_nm, wavelength_nm, irradiance, left=0.0, right=0.0)

    def read(self) -> list[str]:
        integration_s = self.integration_ms / 1000.0
        time.sleep(integration_s * self.averaging)
        light = self.rig_state.light
        self.record("read", light_on=light.on, light_level=light.level, flux_fraction=light.effective_fraction)
        irradiance = self.true_irradiance(0.0 if self.blocked else light.effective_fraction)
        measured, saturated = self.detector.measure(irradiance, integration_s, self.averaging, self.rng)
        rows = [f"{format_float(w)} {value:.6e}" for w, value in zip(self.wavelength_nm, measured, strict=True)]
        return [f"{BLOCK_BEGIN} {len(rows)} {int(saturated)}", *rows, BLOCK_END]
