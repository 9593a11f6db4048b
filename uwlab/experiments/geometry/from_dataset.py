"""The geometry validation from a rig's dataset: its geometry sweeps (``kind = "geometry"``, docs/sweeps.md) measured
with the e-SFR point by point, checked against the model given the rig as the dataset records it.

Per point the prediction is `uwlab.model.mtf.design_mtf50` of the sweep's resolved rig (``metadata.json`` ``rigs``:
the rig as the user described it, never the simulation's truth) at the point's recorded settings: the target at
``target_distance_m`` (from the pupil), the lens focused at ``lens_focus_m`` (air-equivalent, from the pupil), its
``f_number``, the edge at the measured ``edge_angle_deg`` and, for an exposure step, the target moving at the rig's
``operation.speed_m_s`` over ``exposure_us`` along the sensor's rows (at the edge's angle from its normal; the other
steps image a still target). The focus sweep gives the best focus (the step of the highest MTF50, measured and
predicted); the distance sweep the depth of field: the lens is focused on the sweep's ``target_distance_m`` (the plan's,
else the rig's ``operation.altitude_m``), the criterion is the model's MTF50 for a blur the size of the circle of
confusion, the measured limits where the measured MTF50 crosses it, the model's `uwlab.model.optics.dof_underwater`
(`uwlab.experiments.geometry`'s module docstring). One sweep per step enters a validation; the verdict
(`GeometryValidation.adequate`) covers the parts measured.

A colour camera's rows carry the mosaic's green channel in the whole-edge columns (`uwlab.experiments.dataset.
EDGE_FIELDS`), which the validation uses.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import sweep_tables
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.geometry import GeometryValidation, SweepPoint, crossings
from uwlab.model import mtf, optics
from uwlab.model.build import build_design
from uwlab.model.chain import circle_of_confusion_m, port_geometry
from uwlab.model.config import rate_design_sections
from uwlab.model.design import Design
from uwlab.model.focus import target_image_distance_m

CURVE_POINTS = 241  # the model's dense curves in the figure


def has_geometry(points: pd.DataFrame) -> bool:
    """Whether a dataset's points hold geometry sweeps (rows of kind ``geometry``)."""
    return bool(len(points)) and bool((points["kind"] == "geometry").any())


def _design(rig: dict) -> Design:
    return build_design(rate_design_sections(rig), None)


def _predicted(design: Design, row: pd.Series, speed_m_s: float) -> float:
    """The model's MTF50 (cy/px) for one recorded point (module docstring)."""
    angle = abs(float(row["edge_angle_deg"]))
    d = design.with_values(
        **{
            "operation.altitude_m": float(row["target_distance_m"]),
            "operation.speed_m_s": speed_m_s,
            "operation.exposure_s": float(row["exposure_us"]) * 1e-6,
            "lens.f_number": float(row["f_number"]),
        }
    )
    return float(
        mtf.design_mtf50(d, focus_setting_m=float(row["lens_focus_m"]), edge_angle_deg=angle, motion_angle_deg=angle)
    )


def geometry_from_dataset(data: Dataset) -> GeometryValidation:
    """The geometry validation of a dataset's geometry sweeps (module docstring); `ConfigError` for a dataset without
    any, or with two sweeps stepping the same setting."""
    points = data.points()
    if not has_geometry(points):
        raise ConfigError("dataset", str(data.root), 'has no geometry sweep (kind = "geometry")')
    tables = sweep_tables(data.metadata.get("plan") or {})
    rigs = data.metadata.get("rigs") or {}
    rows = points[points["kind"] == "geometry"]
    by_step: dict[str, str] = {}
    for sweep_id in dict.fromkeys(rows["sweep_id"]):
        step = str(tables.get(sweep_id, {}).get("step"))
        if step in by_step:
            raise ConfigError("dataset", str(data.root), f"sweeps {by_step[step]} and {sweep_id} both step {step}")
        if sweep_id not in rigs:
            raise ConfigError("dataset", sweep_id, "no rig recorded for this sweep in metadata.json")
        by_step[step] = sweep_id

    def sweep(step: str) -> tuple[str | None, pd.DataFrame, Design | None]:
        sweep_id = by_step.get(step)
        if sweep_id is None:
            return None, rows.iloc[:0], None
        own = rows[rows["sweep_id"] == sweep_id].sort_values("point_index")
        return sweep_id, own, _design(rigs[sweep_id])

    def measured(own: pd.DataFrame, design: Design, value: str, speed_m_s: float = 0.0, scale: float = 1.0):
        return [
            SweepPoint(float(r[value]) * scale, float(r["mtf50_cy_per_px"]), _predicted(design, r, speed_m_s))
            for _, r in own.iterrows()
        ]

    first = next(iter(by_step.values()))
    reference = _design(rigs[first])
    port, n_w, flat, dome, decenter_z = port_geometry(reference)
    _, focus_rows, focus_design = sweep("lens_focus_m")
    distance_id, distance_rows, distance_design = sweep("target_distance_m")
    if distance_design is not None and distance_id is not None:
        s = float(tables[distance_id].get("target_distance_m", distance_design["operation.altitude_m"]))
    elif focus_design is not None:
        s = float(focus_rows["target_distance_m"].median())
    else:
        s = float(rows["target_distance_m"].median())
    result = GeometryValidation(
        target_distance_m=s,
        focus_image_m=float(target_image_distance_m(s, port, n_w, flat, dome, decenter_z)),
    )
    angle = float(np.median(np.abs(rows["edge_angle_deg"].astype(float))))

    def curve(design: Design, row: pd.Series, column: str, values: np.ndarray) -> list[float]:
        return [_predicted(design, pd.Series({**row.to_dict(), column: v}), 0.0) for v in values]

    if focus_design is not None:
        result.focus = measured(focus_rows, focus_design, "lens_focus_m")
        dense = np.linspace(result.focus[0].value_m, result.focus[-1].value_m, CURVE_POINTS)
        row = focus_rows.iloc[0].copy()
        row["edge_angle_deg"] = angle
        result.focus_curve = (dense.tolist(), curve(focus_design, row, "lens_focus_m", dense))
    if distance_design is not None:
        result.distance = measured(distance_rows, distance_design, "target_distance_m")
        f_m = float(distance_design["lens.focal_length_mm"]) * 1e-3
        f_number = float(distance_rows["f_number"].median())
        coc = float(circle_of_confusion_m(distance_design))
        near, far = optics.dof_underwater(s, f_m, f_number, coc, port, n_w, dome=dome, flat=flat)
        result.dof_model_m = (float(near), float(far))
        pitch = distance_design.sensor.pixel_size_um * 1e-6
        result.criterion_mtf50 = float(
            mtf.mtf50_cy_per_px(
                pixel_pitch_m=pitch, blur_diameter_m=coc, f_number=f_number, edge_angle_rad=np.radians(angle)
            )
        )
        values = np.array([p.value_m for p in result.distance])
        sharpness = np.array([p.measured_mtf50 for p in result.distance])
        result.dof_measured_m = crossings(values, sharpness, result.criterion_mtf50, s)
        dense = np.linspace(values.min(), values.max(), CURVE_POINTS)
        row = distance_rows.iloc[0].copy()
        row["edge_angle_deg"] = angle
        result.distance_curve = (dense.tolist(), curve(distance_design, row, "target_distance_m", dense))
    _, aperture_rows, aperture_design = sweep("f_number")
    if aperture_design is not None:
        result.aperture = measured(aperture_rows, aperture_design, "f_number")
    _, exposure_rows, exposure_design = sweep("exposure_us")
    if exposure_design is not None:
        speed = float(exposure_design["operation.speed_m_s"])
        result.exposure = measured(exposure_rows, exposure_design, "exposure_us", speed, 1e-6)
    lens = reference["lens.focal_length_mm"]
    result.lens = f"{float(lens):g} mm F{float(rows['f_number'].median()):g}, {reference.sensor.name}"
    return result


def main(argv: list[str] | None = None) -> int:
    """``python -m uwlab.experiments.geometry.from_dataset DATASET --out DIR``: ``geometry.json`` and ``geometry.png``
    of a dataset's geometry sweeps into DIR (`uwlab report` finds them; it also computes them from a dataset)."""
    import argparse

    from uwlab.experiments.geometry import write_geometry

    parser = argparse.ArgumentParser(prog="python -m uwlab.experiments.geometry.from_dataset")
    parser.add_argument("dataset")
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    write_geometry(geometry_from_dataset(Dataset.open(args.dataset)), Path(args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
