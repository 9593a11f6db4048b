"""The data behind the paper's design figures, for a scalar design: each function evaluates the model over the
figure's axes (one vectorised call) and returns plain arrays. `plots.py` draws them as PNG files (`uwlab design
--plot`), `uwlab.explore` as interactive figures; both show the same numbers.

- `dof_curves`: near and far limits of acceptable focus against the f-number (for the design's altitude and
  multiples of it) and against the focus distance (for the design's f-number).
- `operation_curves`: minimum framerate (for the overlap) and maximum exposure (for the blur limit) against the
  vehicle speed, for the design's altitude and multiples of it.
- `water_attenuation`: beam attenuation c(λ) of every named water type.
- `quantum_efficiency`: the QE curves of the shipped sensor profiles.
- The spectra along the chain are `uwlab.model.design.stage_spectra`.
"""

from __future__ import annotations

import numpy as np

from uwlab.model.design import Design, evaluate
from uwlab.model.grid import WavelengthGrid
from uwlab.model.sensor import SensorProfile, available_profiles, load_sensor_profile
from uwlab.model.water import WATER_TYPES, water_iop

# Focus distances and altitudes of the families of curves, as multiples of the design's altitude.
ALTITUDE_FACTORS = (0.5, 1.0, 2.0, 4.0)
F_NUMBERS = np.geomspace(1.0, 22.0, 60)
SPEEDS_M_S = np.linspace(0.1, 3.0, 60)
# Focus distances of the depth-of-field-against-distance curve, as multiples of the design's altitude.
DISTANCE_FACTORS = np.geomspace(0.1, 10.0, 81)  # odd: the design's own distance is on the curve


def dof_curves(design: Design) -> dict[str, np.ndarray]:
    """Depth of field of the design's lens and port [m].

    Keys: ``f_number`` (N axis), ``focus_m`` (one distance per curve), ``near_m``/``far_m`` of shape
    (focus, N); ``distance_m`` (focus distance axis) with ``near_at_distance_m``/``far_at_distance_m`` at the
    design's f-number. An unbounded far limit (past the hyperfocal distance) is ``inf``.
    """
    altitude = float(design["operation.altitude_m"])
    focus = altitude * np.asarray(ALTITUDE_FACTORS)
    dof = evaluate(design.with_values(**{"lens.f_number": F_NUMBERS[None, :], "operation.altitude_m": focus[:, None]}))
    distance = altitude * DISTANCE_FACTORS
    along = evaluate(design.with_values(**{"operation.altitude_m": distance}))["dof_m"]
    return {
        "f_number": F_NUMBERS,
        "focus_m": focus,
        "near_m": dof["dof_m"]["near"],
        "far_m": dof["dof_m"]["far"],
        "distance_m": distance,
        "near_at_distance_m": np.broadcast_to(along["near"], distance.shape),
        "far_at_distance_m": np.broadcast_to(along["far"], distance.shape),
    }


def operation_curves(design: Design) -> dict[str, np.ndarray]:
    """Keys: ``speed_m_s`` (axis), ``altitude_m`` (one per curve), ``min_framerate_hz`` and ``max_exposure_s``
    of shape (altitude, speed)."""
    altitudes = float(design["operation.altitude_m"]) * np.asarray(ALTITUDE_FACTORS)
    out = evaluate(
        design.with_values(**{"operation.speed_m_s": SPEEDS_M_S[None, :], "operation.altitude_m": altitudes[:, None]})
    )
    shape = (altitudes.size, SPEEDS_M_S.size)
    return {
        "speed_m_s": SPEEDS_M_S,
        "altitude_m": altitudes,
        "min_framerate_hz": np.broadcast_to(out["min_framerate_hz"], shape),
        "max_exposure_s": np.broadcast_to(out["max_exposure_s"], shape),
    }


def water_attenuation(grid: WavelengthGrid) -> dict[str, np.ndarray]:
    """Beam attenuation c = a + b [1/m] of every named water type on the grid (`uwlab.model.water`)."""
    return {name: water_iop(name, grid).c_per_m for name in WATER_TYPES}


def quantum_efficiency(extra: tuple[SensorProfile, ...] = ()) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{profile name: (wavelength [nm], combined QE)} of the shipped sensor profiles and any `extra` ones."""
    profiles = [load_sensor_profile(name) for name in available_profiles()] + list(extra)
    return {p.name: (p.qe_nm, p.qe["combined"]) for p in dict.fromkeys(profiles)}
