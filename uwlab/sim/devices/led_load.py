"""An LED as a supply's load: forward voltage V(I), its inverse I(V), and the faults a bench sees.

Forward-voltage curve (a diode with a knee offset and series resistance; Shockley's law solved for V, e.g.
Schubert, *Light-Emitting Diodes*, 2nd ed., §4.2 "Deviations from the ideal I–V characteristic", eq. 4.7 with the
series resistance R_s):

    V(I) = V_knee + n·V_T·ln(1 + I/I_s) + I·R_series,    I ≥ 0,   V_T = k_B·T/q

and I(V) = 0 for V ≤ V_knee (a diode below its knee passes no current worth measuring; negative currents are not
modelled). I(V) is V(I)'s inverse, found by Brent's method on the monotonic V(I) (no closed form with R_series > 0
that stays finite in floating point).

Default numbers (assumed, a typical 1 W white power LED such as a Cree XP-G or Lumileds Luxeon: data sheets give
~2.9–3.0 V at 350 mA and ~3.1–3.3 V at 1 A at 25 °C): V_knee = 2.55 V, n = 2.0, I_s = 1 mA, R_series = 0.3 Ω,
T = 298.15 K; this gives 2.96 V at 0.35 A and 3.21 V at 1 A.

Faults (`LOAD_FAULTS`): ``"open"`` (a broken bond wire or unplugged cable: no current at any voltage),
``"short"`` (a few-mΩ load, `SHORT_RESISTANCE_OHM`: the full current at ~0 V).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.optimize import brentq

BOLTZMANN_J_PER_K = 1.380649e-23  # CODATA 2018, exact
ELEMENTARY_CHARGE_C = 1.602176634e-19  # CODATA 2018, exact
SHORT_RESISTANCE_OHM = 0.005  # assumed: leads and a crushed cable, a few mΩ
LOAD_FAULTS = ("open", "short")


@dataclass(frozen=True)
class LedLoad:
    """A forward-biased LED (see the module docstring for the curve and where the numbers come from)."""

    v_knee_v: float = 2.55
    ideality: float = 2.0
    saturation_current_a: float = 1e-3
    r_series_ohm: float = 0.3
    temperature_k: float = 298.15

    def __post_init__(self):
        if not (self.v_knee_v >= 0 and self.ideality > 0 and self.saturation_current_a > 0):
            raise ValueError("LedLoad needs v_knee_v >= 0, ideality > 0, saturation_current_a > 0")
        if not (self.r_series_ohm >= 0 and self.temperature_k > 0):
            raise ValueError("LedLoad needs r_series_ohm >= 0 and temperature_k > 0")

    @property
    def thermal_voltage_v(self) -> float:
        return BOLTZMANN_J_PER_K * self.temperature_k / ELEMENTARY_CHARGE_C

    def voltage_v(self, current_a: float) -> float:
        """Forward voltage at ``current_a`` (≥ 0)."""
        if current_a < 0:
            raise ValueError(f"LED current must be >= 0 A, got {current_a}")
        slope_v = self.ideality * self.thermal_voltage_v
        return (
            self.v_knee_v + slope_v * math.log1p(current_a / self.saturation_current_a) + current_a * self.r_series_ohm
        )

    def current_a(self, voltage_v: float) -> float:
        """Forward current at ``voltage_v``: 0 at or below the knee, else V(I)'s inverse (to ~1e-12 A)."""
        if voltage_v <= self.v_knee_v:
            return 0.0
        # V(I) ≥ V_knee + I·R and ≥ V_knee + n·V_T·ln(1 + I/I_s): either bound gives an I with V(I) ≥ voltage_v.
        excess = voltage_v - self.v_knee_v
        upper = excess / self.r_series_ohm if self.r_series_ohm > 0 else math.inf
        slope_v = self.ideality * self.thermal_voltage_v
        upper = min(upper, self.saturation_current_a * math.expm1(min(excess / slope_v, 700.0)))
        return float(brentq(lambda i: self.voltage_v(i) - voltage_v, 0.0, upper, xtol=1e-13, rtol=1e-12))


@dataclass(frozen=True)
class LoadState:
    """The load a supply sees: an LED, or that LED with a fault (``None``, ``"open"`` or ``"short"``)."""

    led: LedLoad = LedLoad()
    fault: str | None = None

    def __post_init__(self):
        if self.fault not in (None, *LOAD_FAULTS):
            raise ValueError(f"load fault must be None or one of {', '.join(LOAD_FAULTS)}, got {self.fault!r}")

    def voltage_v(self, current_a: float) -> float:
        """Voltage across the load at ``current_a``; ``inf`` for an open load carrying any current."""
        if self.fault == "open":
            return 0.0 if current_a == 0 else math.inf
        if self.fault == "short":
            return current_a * SHORT_RESISTANCE_OHM
        return self.led.voltage_v(current_a)

    def current_a(self, voltage_v: float) -> float:
        """Current the load draws at ``voltage_v`` (≥ 0)."""
        if self.fault == "open" or voltage_v <= 0:
            return 0.0
        if self.fault == "short":
            return voltage_v / SHORT_RESISTANCE_OHM
        return self.led.current_a(voltage_v)
