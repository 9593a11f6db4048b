"""Simulated ChArUco image sets through a design's port, in air or in water, with their true poses.

The camera is the design's sensor and lens: an ideal pinhole of focal length `lens.focal_length_mm` (optionally
with radial distortion k1, OpenCV's convention) whose principal point is the image centre, on a sensor rendered
at 1/`downsample` of its resolution (pixels `downsample` times larger, same area, the per-pixel noise model of
the sensor profile unchanged). The port is the design's (`uwlab.model.port_field.port_of`: dimensions, indices,
decentring, tilt); in air the outside medium has index 1. Poses are drawn from a seeded generator: the board's
centre within the central part of the field, at 0.6–1.6 times the distance at which its width fills the
field in that medium, tilted up to ±45° about x and y and ±20° about the axis, and kept only if at least 80 % of
its corners land inside the image. The board's white gets `white_fraction` of the full well; the sensor's noise
is that of `uwlab.sim.devices.camera.SimSensor` (shot, dark, quantisation, fixed patterns).

Writes `pose-NNN.png` (8-bit) and `charuco.json`: the board, the camera, the port as rendered, the medium and
each image's true pose (rvec [rad, Rodrigues], tvec [m]; OpenCV's convention X_cam = R X_board + t).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from uwlab.sim.devices.camera import RateMap, SensorConfig, SimSensor, SimTruth
from uwlab.sim.target import PlanarTarget, TargetView
from uwlab.errors import ConfigError, UwlabError
from uwlab.experiments.port.board import WHITE_REFLECTANCE, CharucoBoard
from uwlab.jsonable import to_jsonable
from uwlab.model.lens import BrownLens
from uwlab.model.port_field import exact_fov_rad, port_of
from uwlab.model.raytrace import DomePort, FlatPort, Port
from uwlab.model.schema import Seed, check, limits
from uwlab.outputs import output_dir

# Images of one simulated set: a calibration uses 10–50; more than 1000 is a typo (each pose is a render).
PoseCount = Annotated[int, limits(1, 1000, "poses", hint="", integer=True)]
# OpenCV's k1 on normalised image coordinates: real lenses, fisheyes included, stay well within ±1
LensK1 = Annotated[float, limits(-1.0, 1.0, "", hint="k1 of normalised coordinates (OpenCV), not of pixels")]

MEDIA = ("air", "water")
SIDECAR = "charuco.json"
EXPOSURE_US = 10_000.0
DISTANCE_RANGE = (0.6, 1.6)
CENTRE_SPREAD = 0.35
TILT_DEG = (45.0, 45.0, 20.0)
MIN_VISIBLE = 0.8
MAX_TEXELS = 8192


def camera_of(design, downsample: int, k1: float = 0.0) -> tuple[BrownLens, tuple[int, int], float]:
    """(lens, resolution, pixel size [m]) of the design's camera rendered at 1/downsample of its resolution."""
    if downsample < 1 or any(n // downsample < 64 for n in design.sensor.resolution_px):
        raise ConfigError("--downsample", downsample, "must be >= 1 and leave at least 64 pixels per side")
    width, height = (n // downsample for n in design.sensor.resolution_px)
    pixel = design.sensor.pixel_size_um * 1e-6 * downsample
    f_px = float(design["lens.focal_length_mm"]) * 1e-3 / pixel
    return BrownLens(f_px, f_px, (width - 1) / 2, (height - 1) / 2, (k1, 0.0, 0.0, 0.0, 0.0)), (width, height), pixel


def port_in(design, medium: str) -> Port:
    if medium not in MEDIA:
        raise ConfigError("--medium", medium, f"must be one of {', '.join(MEDIA)}")
    port = port_of(design)
    return port.in_medium(1.0) if medium == "air" else port


def sample_poses(board: CharucoBoard, lens: BrownLens, resolution, port: Port, count: int, rng) -> list:
    """`count` (R, t) board poses seen by the camera (module docstring), drawn from `rng`."""
    width, height = resolution
    sensor_size = (width / lens.fx, height / lens.fy)
    half = {axis: angle / 2 for axis, angle in exact_fov_rad(port, sensor_size, 1.0).items()}
    fill = board.size_m[0] / (2 * math.tan(half["x"]))
    centre_board = np.array([board.size_m[0] / 2, board.size_m[1] / 2, 0.0])
    corners = board.corners_m
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(200 * count):
        if len(poses) == count:
            break
        distance = fill * rng.uniform(*DISTANCE_RANGE)
        u, v = (CENTRE_SPREAD * rng.uniform(-1, 1) * math.tan(half[a]) for a in "xy")
        rotation = Rotation.from_euler("xyz", [rng.uniform(-t, t) for t in TILT_DEG], degrees=True).as_matrix()
        t = distance * np.array([u, v, 1.0]) - rotation @ centre_board
        pixels = lens.pixels(port.project(corners @ rotation.T + t))
        inside = (
            np.all(np.isfinite(pixels), axis=1)
            & (pixels[:, 0] > 8)
            & (pixels[:, 0] < width - 9)
            & (pixels[:, 1] > 8)
            & (pixels[:, 1] < height - 9)
        )
        if inside.mean() >= MIN_VISIBLE:
            poses.append((rotation, t))
    if len(poses) < count:
        raise UwlabError(f"could only place {len(poses)} of {count} board poses in the field of view")
    return poses


def _texture(board: CharucoBoard, lens: BrownLens, distance_m: float, supersample: int):
    """The board texture, at least as fine as the sample spacing at `distance_m` (capped at MAX_TEXELS a side)."""
    spacing = distance_m / lens.fx / supersample
    per_square = math.ceil(board.square_m / spacing)
    per_square = min(per_square, MAX_TEXELS // (board.squares[0] + 2))
    return board.texture(per_square / board.square_m)


def _fixed_map(rate: np.ndarray) -> RateMap:
    """The electron-rate map of one rendered pose, whatever shape is asked."""
    return lambda shape: rate


def _port_record(port: Port) -> dict:
    if isinstance(port, DomePort):
        return {
            "port": "dome",
            "outer_radius_mm": port.outer_radius_m * 1e3,
            "thickness_mm": port.thickness_m * 1e3,
            "glass_index": port.glass_index,
            "outside_index": port.water_index,
            "decenter_mm": [v * 1e3 for v in port.decenter_m],
        }
    if not isinstance(port, FlatPort):
        raise TypeError(f"unknown port {type(port).__name__}")
    return {
        "port": "flat",
        "thickness_mm": port.thickness_m * 1e3,
        "air_gap_mm": port.air_gap_m * 1e3,
        "glass_index": port.glass_index,
        "outside_index": port.water_index,
        "tilt_deg": [math.degrees(v) for v in port.tilt_rad],
    }


def simulate_charuco(
    design,
    board: CharucoBoard,
    medium: str,
    count: int,
    out: str | Path,
    seed: int = 0,
    downsample: int = 4,
    k1: float = 0.0,
    white_fraction: float = 0.6,
    supersample: int = 4,
) -> dict:
    """Render `count` images of `board` seen through the design's port in `medium` into the new folder `out`;
    returns the sidecar record (also written as charuco.json)."""
    count = check(PoseCount, count, "--poses")
    seed = check(Seed, seed, "--seed")
    k1 = check(LensK1, k1, "--lens-k1")
    if not 0 < white_fraction <= 1:
        raise ConfigError("white_fraction", white_fraction, "must be in (0, 1]")
    port = port_in(design, medium)
    lens, resolution, pixel = camera_of(design, downsample, k1)
    rng = np.random.default_rng(seed)
    poses = sample_poses(board, lens, resolution, port, count, rng)
    folder = output_dir(out, "--out", empty=True)
    folder.mkdir(exist_ok=True)
    closest = min(float(np.linalg.norm(t + r @ np.array([*np.array(board.size_m) / 2, 0.0]))) for r, t in poses)
    reflectance, texel, origin = _texture(board, lens, closest, supersample)
    target = PlanarTarget(reflectance, texel, origin, background=0.1)
    view = TargetView(lens, resolution, port, supersample)
    truth = SimTruth.from_sensor_profile(
        design.sensor, resolution_px=resolution, pixel_size_um=design.sensor.pixel_size_um * downsample
    )
    sensor = SimSensor(truth, lambda shape: np.zeros(shape, np.float32), seed=seed)
    config = SensorConfig(EXPOSURE_US, truth.gain_min_db, 0.0, "Mono8", 0, 0, *resolution)
    electrons_white = white_fraction * truth.saturation_e
    records = []
    for index, (rotation, t) in enumerate(poses):
        image_reflectance = view.reflectance_image(target, rotation, t)
        rate = image_reflectance / WHITE_REFLECTANCE * electrons_white / (EXPOSURE_US * 1e-6)
        sensor.set_rate_map(_fixed_map(rate))
        name = f"pose-{index:03d}.png"
        if not cv2.imwrite(str(folder / name), sensor.render(config)):
            raise UwlabError(f"could not write {folder / name}")
        records.append({"image": name, "rvec": cv2.Rodrigues(rotation)[0].ravel(), "tvec_m": t})
    sidecar = {
        "medium": medium,
        "seed": seed,
        "board": board.to_dict(),
        "camera": {
            "resolution_px": list(resolution),
            "pixel_size_um": pixel * 1e6,
            "focal_length_mm": float(design["lens.focal_length_mm"]),
            "focal_length_px": lens.fx,
            "principal_point_px": [lens.cx, lens.cy],
            "distortion": list(lens.distortion),
            "downsample": downsample,
            "sensor": design.sensor.name,
        },
        "port": _port_record(port),
        "poses": records,
    }
    (folder / SIDECAR).write_text(json.dumps(to_jsonable(sidecar), indent=2) + "\n")
    return sidecar
