"""The geometry validation on the simulated tank (`uwlab.experiments.geometry`'s module docstring): the images from
`uwlab.sim.edge_chart`, the predictions from `uwlab.model.mtf` and `uwlab.model.optics` given the rig as a user
describes it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uwlab.experiments.frames.esfr import slanted_edge
from uwlab.experiments.geometry import EDGE_ANGLE_DEG, GeometryValidation, SweepPoint, crossings
from uwlab.model import mtf, optics
from uwlab.model import port as port_model
from uwlab.model.chain import circle_of_confusion_m
from uwlab.sim.edge_chart import render_edge, rig_optics
from uwlab.sim.scene import RigScene


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
    scene = RigScene.from_toml(rig)
    world = scene.world
    design = scene.design.with_values(**{"lens.focal_length_mm": focal_length_mm, "lens.f_number": f_number})
    sensor = design.sensor
    n_w = float(design["housing.water_index"])
    optics_ = rig_optics(design, world, tank=True, f_number=f_number)
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
    result.dof_measured_m = crossings(values, sharpness, result.criterion_mtf50, s)
    dense = np.linspace(result.focus[0].value_m, result.focus[-1].value_m, 241)
    result.focus_curve = (dense.tolist(), [predicted(image_m, v) for v in dense])
    dense = np.linspace(values[0], values[-1], 241)
    images = port_model.flat_apparent_distance(dense, n_w, *flat)
    result.distance_curve = (dense.tolist(), [predicted(float(v), image_m) for v in images])
    result.lens = f"{focal_length_mm:g} mm F{f_number:g}, {sensor.name}"
    return result


def main(argv: list[str] | None = None) -> int:
    """``python -m uwlab.experiments.geometry.tank --out DIR [--rig RIG.toml] [--seed N]``: the validation into DIR,
    as its own process (`uwlab demo` runs it beside the fit, on the other core)."""
    import argparse

    from uwlab.experiments.geometry import write_geometry

    parser = argparse.ArgumentParser(prog="python -m uwlab.experiments.geometry.tank")
    parser.add_argument("--out", required=True)
    parser.add_argument("--rig")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    write_geometry(validate_tank_geometry(args.rig, seed=args.seed), Path(args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
