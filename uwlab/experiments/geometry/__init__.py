"""The paper's geometry measured: MTF50 against focus setting and target distance, the best focus and the depth of
field, measured with the slanted-edge MTF (`uwlab.experiments.frames.esfr`) and checked against the model's
predictions (`uwlab.model.mtf`, `uwlab.model.optics`).

On the simulated tank (`uwlab.experiments.geometry.tank.validate_tank_geometry`) the images come from
`uwlab.sim.edge_chart`, which blurs the chart by ray sampling through the tank's own wall geometry; the model is
given the rig as a user would describe it (a flat port with the wall's air gap, thickness and index; the board's
distance; the lens) and knows nothing else.

- Focus sweep: the lens focus setting (air-equivalent distance from the pupil, as `uwlab port trace` reports it)
  steps through the target's image distance; measured MTF50 per step against the predicted; the measured best
  focus is the step of the highest measured MTF50, the predicted best the step of the highest prediction.
- Depth of field: the target steps through distances with the lens focused on the design's target; a point is
  acceptably sharp where its MTF50 is at least the criterion, the MTF50 the model predicts for a blur disk the size
  of the circle of confusion (`operation.circle_of_confusion_mm`, default the sensor diagonal / 1500: the blur the
  DoF formula accepts); the measured limits are where the measured MTF50 crosses the criterion (linear
  interpolation between steps), the model's `uwlab.model.optics.dof_underwater`. They are compared as depths
  (limit − focused distance), the stricter comparison.

The verdict (`GeometryValidation.adequate`) holds the measurements to the issue's targets for the simulated tank:
every MTF50 within `MTF50_TOLERANCE` of its prediction, the measured best focus within one step of the predicted,
and both measured depths within `DEPTH_TOLERANCE` of the model's. `write_geometry` writes ``geometry.json`` and
``geometry.png`` (the report's geometry section).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from uwlab.experiments.figures import LABEL_PT, PALETTE, TICK_PT, Figure, save_figure
from uwlab.jsonable import to_jsonable
from uwlab.outputs import output_dir
from uwlab.provenance import provenance

EDGE_ANGLE_DEG = 5.0
MTF50_TOLERANCE = 0.05
DEPTH_TOLERANCE = 0.10
GEOMETRY_FILE = "geometry.json"
GEOMETRY_FIGURE = "geometry.png"


@dataclass
class SweepPoint:
    value_m: float  # the focus setting or the target distance stepped (an aperture sweep: the f-number; an
    # exposure sweep: the exposure in seconds)
    measured_mtf50: float
    predicted_mtf50: float

    @property
    def error(self) -> float:
        return self.measured_mtf50 / self.predicted_mtf50 - 1.0


@dataclass
class GeometryValidation:
    """A focus sweep and a distance sweep, with the measured and predicted best focus and depth of field; a rig's
    geometry sweeps (`uwlab.experiments.geometry.from_dataset`) may also step the f-number (``aperture``) or the
    exposure with a moving target (``exposure``). A part not measured (an empty sweep) is left out of the verdict
    and reads NaN."""

    target_distance_m: float
    focus_image_m: float  # the target's image distance (where the model says to focus)
    focus: list[SweepPoint] = field(default_factory=list)
    distance: list[SweepPoint] = field(default_factory=list)
    criterion_mtf50: float = float("nan")
    dof_measured_m: tuple[float, float] = (float("nan"), float("nan"))
    dof_model_m: tuple[float, float] = (float("nan"), float("nan"))
    # The model's curves, densely: (values, MTF50) against focus setting and against target distance.
    focus_curve: tuple[list[float], list[float]] = ([], [])
    distance_curve: tuple[list[float], list[float]] = ([], [])
    lens: str = ""
    aperture: list[SweepPoint] = field(default_factory=list)
    exposure: list[SweepPoint] = field(default_factory=list)

    @property
    def focus_step_m(self) -> float:
        if len(self.focus) < 2:
            return float("nan")
        return float(np.median(np.diff([p.value_m for p in self.focus])))

    @property
    def best_focus_measured_m(self) -> float:
        if not self.focus:
            return float("nan")
        return self.focus[int(np.argmax([p.measured_mtf50 for p in self.focus]))].value_m

    @property
    def best_focus_predicted_m(self) -> float:
        if not self.focus:
            return float("nan")
        return self.focus[int(np.argmax([p.predicted_mtf50 for p in self.focus]))].value_m

    @property
    def worst_mtf50_error(self) -> float:
        points = [*self.focus, *self.distance, *self.aperture, *self.exposure]
        return float(max(abs(p.error) for p in points)) if points else float("nan")

    def depth_errors(self) -> tuple[float, float]:
        """Relative errors of the measured near and far depths (limit − target distance) against the model's."""
        s = self.target_distance_m
        return tuple(  # type: ignore[return-value]
            (measured - s) / (model - s) - 1.0
            for measured, model in zip(self.dof_measured_m, self.dof_model_m, strict=True)
        )

    @property
    def best_focus_steps_off(self) -> int | None:
        """Steps between the measured and the predicted best focus (None without a focus sweep of 2 points)."""
        if len(self.focus) < 2:
            return None
        return int(round(abs(self.best_focus_measured_m - self.best_focus_predicted_m) / self.focus_step_m))

    @property
    def adequate(self) -> bool:
        steps = self.best_focus_steps_off
        return bool(
            self.worst_mtf50_error <= MTF50_TOLERANCE
            and (steps is None or steps <= 1)
            and (not self.distance or all(abs(e) <= DEPTH_TOLERANCE for e in self.depth_errors()))
        )

    def headline(self) -> str:
        """The comparison in one clause (the report's verdict box; `uwlab demo` prints it after the word)."""
        parts = [f"MTF50 within {100 * self.worst_mtf50_error:.1f} % of the model"]
        if self.best_focus_steps_off is not None:
            parts.append(f"best focus {self.best_focus_steps_off} step(s) off")
        if self.distance:
            near_error, far_error = self.depth_errors()
            parts.append(f"depth of field near {100 * near_error:+.1f} %, far {100 * far_error:+.1f} %")
        return "; ".join(parts)

    def to_json(self) -> dict:
        near_error, far_error = self.depth_errors()
        return {
            "adequate": self.adequate,
            "headline": self.headline(),
            "lens": self.lens,
            "tolerances": {"mtf50": MTF50_TOLERANCE, "depth": DEPTH_TOLERANCE, "best_focus_steps": 1},
            "focus_curve": {"focus_setting_m": self.focus_curve[0], "mtf50_cy_per_px": self.focus_curve[1]},
            "distance_curve": {"distance_m": self.distance_curve[0], "mtf50_cy_per_px": self.distance_curve[1]},
            "target_distance_m": self.target_distance_m,
            "focus_image_m": self.focus_image_m,
            "focus_sweep": [vars(p) for p in self.focus],
            "distance_sweep": [vars(p) for p in self.distance],
            "aperture_sweep": [vars(p) for p in self.aperture],
            "exposure_sweep": [vars(p) for p in self.exposure],
            "best_focus_measured_m": self.best_focus_measured_m,
            "best_focus_predicted_m": self.best_focus_predicted_m,
            "focus_step_m": self.focus_step_m,
            "worst_mtf50_error": self.worst_mtf50_error,
            "criterion_mtf50_cy_per_px": self.criterion_mtf50,
            "dof_measured_m": list(self.dof_measured_m),
            "dof_model_m": list(self.dof_model_m),
            "dof_depth_errors": [near_error, far_error],
        }


def crossings(values: np.ndarray, sharpness: np.ndarray, level: float, centre: float) -> tuple[float, float]:
    """Where ``sharpness`` falls below ``level`` on each side of ``centre`` (linear interpolation); NaN where it
    does not within the sweep."""
    limits = []
    for side in (-1, 1):
        order = np.argsort(side * (values - centre))
        v, s = values[order], sharpness[order]
        v, s = v[side * (v - centre) >= 0], s[side * (v - centre) >= 0]
        below = np.flatnonzero(s < level)
        if below.size == 0 or below[0] == 0:
            limits.append(float("nan"))
            continue
        i = below[0]
        limits.append(float(v[i - 1] + (s[i - 1] - level) * (v[i] - v[i - 1]) / (s[i - 1] - s[i])))
    return limits[0], limits[1]


def plot_geometry(result: GeometryValidation) -> Figure:
    """MTF50 against the focus setting and against the target distance: the model's curve drawn over the measured
    points; the MTF50 criterion and the measured and modelled depth-of-field limits (`uwlab.experiments.figures`
    rules)."""
    fig = Figure(figsize=(11.0, 4.0))
    left, right = fig.subplots(1, 2)
    focus = [p.value_m for p in result.focus]
    left.plot(focus, [p.measured_mtf50 for p in result.focus], "o", color=PALETTE["orange"], label="measured (e-SFR)")
    left.plot(*result.focus_curve, color=PALETTE["blue"], linewidth=1.6, label="model", zorder=3)
    left.axvline(result.focus_image_m, color=PALETTE["black"], linestyle=":", linewidth=1, label="target's image")
    left.set_xlabel("lens focus setting [m, air-equivalent]", fontsize=LABEL_PT)
    left.set_ylabel("MTF50 [cycles/pixel]", fontsize=LABEL_PT)
    left.set_title(f"Focus sweep, board at {result.target_distance_m:.3f} m", fontsize=LABEL_PT)
    distance = [p.value_m for p in result.distance]
    right.plot(distance, [p.measured_mtf50 for p in result.distance], "o", color=PALETTE["orange"], label="measured")
    right.plot(*result.distance_curve, color=PALETTE["blue"], linewidth=1.6, label="model", zorder=3)
    right.axhline(result.criterion_mtf50, color=PALETTE["black"], linestyle=":", linewidth=1, label="criterion (CoC)")
    for i, limit in enumerate(result.dof_model_m):
        right.axvline(limit, color=PALETTE["blue"], linestyle="--", linewidth=1, label="model DoF" if i == 0 else None)
    for i, limit in enumerate(result.dof_measured_m):
        label = "measured DoF" if i == 0 else None
        right.axvline(limit, color=PALETTE["orange"], linestyle="-.", linewidth=1, label=label)
    right.set_xlabel("target distance [m]", fontsize=LABEL_PT)
    right.set_title("Depth of field, focused on the board", fontsize=LABEL_PT)
    for ax in (left, right):
        ax.tick_params(labelsize=TICK_PT)
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=TICK_PT - 1, frameon=False)
    fig.tight_layout()
    return fig


def write_geometry(result: GeometryValidation, out: Path) -> Path:
    """``geometry.json`` and ``geometry.png`` into the directory ``out`` (created; its parent must exist)."""
    out = output_dir(out, "--out", empty=True)
    out.mkdir(exist_ok=True)
    record = {**result.to_json(), "provenance": provenance()}
    (out / GEOMETRY_FILE).write_text(json.dumps(to_jsonable(record), indent=2) + "\n")
    save_figure(plot_geometry(result), out / GEOMETRY_FIGURE)
    return out
