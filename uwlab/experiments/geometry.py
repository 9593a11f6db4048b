"""The paper's geometry measured: MTF50 against focus setting and target distance, the best focus and the depth of
field, measured with the slanted-edge MTF (`uwlab.experiments.frames.esfr`) and checked against the model's
predictions (`uwlab.model.mtf`, `uwlab.model.optics`).

On the simulated tank (`validate_tank_geometry`) the images come from `uwlab.sim.edge_chart`, which blurs the chart
by ray sampling through the tank's own wall geometry; the model is given the rig as a user would describe it (a
flat port with the wall's air gap, thickness and index; the board's distance; the lens) and knows nothing else.

- Focus sweep: the lens focus setting (air-equivalent distance from the pupil, as `uwlab port trace` reports it)
  steps through the target's image distance; measured MTF50 per step against the predicted; the measured best
  focus is the step of the highest measured MTF50, the predicted best the step of the highest prediction.
- Depth of field: the target steps through distances with the lens focused on the design's target; a point is
  acceptably sharp where its MTF50 is at least the criterion, the MTF50 the model predicts for a blur disk the size
  of the circle of confusion (`operation.circle_of_confusion_mm`, default the sensor diagonal / 1500: the blur the
  DoF formula accepts); the measured limits are where the measured MTF50 crosses the criterion (linear
  interpolation between steps), the model's `uwlab.model.optics.dof_underwater`. They are compared as depths
  (limit − focused distance), the stricter comparison.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from uwlab.experiments.frames.esfr import slanted_edge
from uwlab.model import mtf, optics
from uwlab.model import port as port_model

EDGE_ANGLE_DEG = 5.0


@dataclass
class SweepPoint:
    value_m: float  # the focus setting or the target distance stepped
    measured_mtf50: float
    predicted_mtf50: float

    @property
    def error(self) -> float:
        return self.measured_mtf50 / self.predicted_mtf50 - 1.0


@dataclass
class GeometryValidation:
    """A focus sweep and a distance sweep, with the measured and predicted best focus and depth of field."""

    target_distance_m: float
    focus_image_m: float  # the target's image distance (where the model says to focus)
    focus: list[SweepPoint] = field(default_factory=list)
    distance: list[SweepPoint] = field(default_factory=list)
    criterion_mtf50: float = float("nan")
    dof_measured_m: tuple[float, float] = (float("nan"), float("nan"))
    dof_model_m: tuple[float, float] = (float("nan"), float("nan"))

    @property
    def focus_step_m(self) -> float:
        return float(np.median(np.diff([p.value_m for p in self.focus])))

    @property
    def best_focus_measured_m(self) -> float:
        return self.focus[int(np.argmax([p.measured_mtf50 for p in self.focus]))].value_m

    @property
    def best_focus_predicted_m(self) -> float:
        return self.focus[int(np.argmax([p.predicted_mtf50 for p in self.focus]))].value_m

    @property
    def worst_mtf50_error(self) -> float:
        return float(max(abs(p.error) for p in [*self.focus, *self.distance]))

    def depth_errors(self) -> tuple[float, float]:
        """Relative errors of the measured near and far depths (limit − target distance) against the model's."""
        s = self.target_distance_m
        return tuple(  # type: ignore[return-value]
            (measured - s) / (model - s) - 1.0
            for measured, model in zip(self.dof_measured_m, self.dof_model_m, strict=True)
        )

    def to_json(self) -> dict:
        near_error, far_error = self.depth_errors()
        return {
            "target_distance_m": self.target_distance_m,
            "focus_image_m": self.focus_image_m,
            "focus_sweep": [vars(p) for p in self.focus],
            "distance_sweep": [vars(p) for p in self.distance],
            "best_focus_measured_m": self.best_focus_measured_m,
            "best_focus_predicted_m": self.best_focus_predicted_m,
            "focus_step_m": self.focus_step_m,
            "worst_mtf50_error": self.worst_mtf50_error,
            "criterion_mtf50_cy_per_px": self.criterion_mtf50,
            "dof_measured_m": list(self.dof_measured_m),
            "dof_model_m": list(self.dof_model_m),
            "dof_depth_errors": [near_error, far_error],
        }


def _crossings(values: np.ndarray, sharpness: np.ndarray, level: float, centre: float) -> tuple[float, float]:
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


def validate_tank_geometry(
    rig: str | Path | None = None,
    *,
    focal_length_mm: float = 12.0,
    f_number: float = 4.0,
    focus_steps: int = 13,
    focus_span: float = 0.12,
    distance_steps: int = 17,
    seed: int = 0,
) -> GeometryValidation:
    """Measure the simulated tank's geometry (module docstring): ``focus_steps`` focus settings over ±``focus_span``
    (relative) around the target's image distance, and ``distance_steps`` board distances across twice the model's
    depth of field, with the rig's camera fitted with a ``focal_length_mm`` lens at ``f_number``."""
    from uwlab.model.chain import circle_of_confusion_m
    from uwlab.sim.edge_chart import TankOptics, render_edge
    from uwlab.sim.scene import RigScene

    scene = RigScene.from_toml(rig)
    world, design = scene.world, scene.design
    sensor = design.sensor
    n_w = float(design["housing.water_index"])
    optics_ = TankOptics(
        focal_length_m=focal_length_mm * 1e-3,
        f_number=f_number,
        pixel_pitch_m=sensor.pixel_size_um * 1e-6,
        camera_gap_m=world.camera_gap_m,
        wall_thickness_m=world.wall_thickness_m,
        wall_index=world.wall_index,
        water_index=n_w,
    )
    s = world.camera_gap_m + world.wall_thickness_m + world.tank_size_m[2]  # the board on the far wall
    flat = (world.camera_gap_m, world.wall_thickness_m, world.wall_index)  # the rig as the user describes it
    f_m, pitch = focal_length_mm * 1e-3, sensor.pixel_size_um * 1e-6
    angle = np.radians(EDGE_ANGLE_DEG)
    k = float(sensor.gain_k(0.0, sensor.bit_depth))
    exposure = dict(k_dn_per_e=k, dark_noise_e=sensor.dark_noise_e, bit_depth=sensor.bit_depth)
    exposure["bright_e"] = 0.6 * sensor.saturation_e
    exposure["dark_e"] = 0.06 * sensor.saturation_e  # the chart's black at 4 % against white at 80 % (assumed)

    def predicted(image_m, focus_m):
        blur = mtf.defocus_blur_diameter_m(image_m, focus_m, f_m, f_number)
        return float(
            mtf.mtf50_cy_per_px(pixel_pitch_m=pitch, blur_diameter_m=blur, f_number=f_number, edge_angle_rad=angle)
        )

    def measured(distance_m, focus_m, index):
        image = render_edge(
            optics_, distance_m, focus_m, angle_deg=EDGE_ANGLE_DEG, seed=seed * 1000 + index, **exposure
        )
        return slanted_edge(image).mtf50_cy_per_px

    image_m = float(port_model.flat_apparent_distance(s, n_w, *flat))
    result = GeometryValidation(target_distance_m=s, focus_image_m=image_m)
    for i, factor in enumerate(np.linspace(1 - focus_span, 1 + focus_span, focus_steps)):
        focus_m = image_m * factor
        result.focus.append(SweepPoint(focus_m, measured(s, focus_m, i), predicted(image_m, focus_m)))

    coc = float(circle_of_confusion_m(design))
    near, far = optics.dof_underwater(s, f_m, f_number, coc, "flat", n_w, flat=flat)
    result.dof_model_m = (float(near), float(far))
    result.criterion_mtf50 = float(
        mtf.mtf50_cy_per_px(pixel_pitch_m=pitch, blur_diameter_m=coc, f_number=f_number, edge_angle_rad=angle)
    )
    span = 2.0 * (float(far) - float(near))
    for i, distance in enumerate(np.linspace(s - span, s + span, distance_steps)):
        image = float(port_model.flat_apparent_distance(distance, n_w, *flat))
        point = SweepPoint(float(distance), measured(distance, image_m, 100 + i), predicted(image, image_m))
        result.distance.append(point)
    values = np.array([p.value_m for p in result.distance])
    sharpness = np.array([p.measured_mtf50 for p in result.distance])
    result.dof_measured_m = _crossings(values, sharpness, result.criterion_mtf50, s)
    return result
