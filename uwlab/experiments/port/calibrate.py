"""Port calibration from ChArUco images: the lens in air, then the port from the images in water.

1. Detect the ChArUco corners (OpenCV `CharucoDetector`) in every image of both folders; views with fewer than
   `MIN_CORNERS` corners are dropped, and too few usable views is a refusal (one line).
2. Lens, in air: OpenCV's `calibrateCamera` (Zhang, "A flexible new technique for camera calibration", IEEE
   PAMI 22(11), 2000) with k1, k2, p1, p2 (k3 fixed at 0): intrinsics and distortion of `uwlab.model.lens`.
3. Port: every corner is reprojected through the exact port (`uwlab.model.raytrace`; scene point → ray by
   `Port.project`, ray → pixel by the lens), the views in water through the port in water and the views in air
   through the same port in air (the housing stays closed between the two sets). Free: the port (dome: the
   pupil's offset from the dome centre x, y, z [mm]; flat: the pupil → inner-face distance [mm] and the tilt of
   the port's normal about x and y [deg]), the lens (starting from step 2, refined jointly so that its
   uncertainty enters the port's), each view's pose (6 nuisance parameters) and, when the lens was refocused
   between the sets, its focal scale s in water (focal length in water / in air; behind a dome it trades off
   against the axial decentring, whose uncertainty then grows several-fold). Levenberg–Marquardt
   (`scipy.optimize.least_squares`, method "lm") on the pixel residuals with a central-difference Jacobian in
   which each pose coordinate of all views is one evaluation (views touch disjoint residuals); corners off by
   more than `OUTLIER_SIGMA` RMS are dropped once and the fit repeated.
4. Uncertainties: the covariance σ² (JᵀJ)⁻¹ at the optimum with σ² = Σr² / (m − n) (Gauss–Newton; e.g.
   Hartley & Zisserman, Multiple View Geometry, 2nd ed., §5.2). The focal ratio f_uw/f_air = s · (the port's
   f_uw/f, `uwlab.model.port_field.focal_ratio`: objects at infinity) gets its standard deviation by the delta
   method.
5. A dome is centred well enough when the radial distortion the fitted decentring adds at the image corners
   (`uwlab.model.port_field.port_distortion`, objects at infinity) stays within `max_distortion_px` for this
   lens and image size.

The RMS reprojection error is per corner, √(mean of dx² + dy²) (as OpenCV reports it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import NotRequired, TypedDict

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from uwlab.errors import ConfigError, UwlabError
from uwlab.experiments.port.board import CharucoBoard, Detection, detect
from uwlab.model.lens import BrownLens
from uwlab.model.data import MAX_BINARY_BYTES, check_input_file
from uwlab.model.port_field import focal_ratio, port_distortion
from uwlab.model.raytrace import DomePort, FlatPort, Port

IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")
MIN_CORNERS = 6
MIN_AIR_VIEWS = 3
MIN_WATER_VIEWS = 2
OUTLIER_SIGMA = 5.0
DEFAULT_MAX_DISTORTION_PX = 0.5
PORT_PARAMETERS = {
    "dome": ("decenter_x_mm", "decenter_y_mm", "decenter_z_mm"),
    "flat": ("port_distance_mm", "tilt_x_deg", "tilt_y_deg"),
}


def to_8bit(image: np.ndarray) -> np.ndarray:
    """A grey 8-bit image for detection: colour to grey; 16-bit scaled so its 99.9th percentile is 255."""
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.dtype == np.uint8:
        return image
    top = max(float(np.percentile(image, 99.9)), 1.0)
    return np.clip(image.astype(np.float64) * (255.0 / top), 0, 255).astype(np.uint8)


def read_views(board: CharucoBoard, folder: str | Path, option: str) -> tuple[list[Detection], tuple[int, int], int]:
    """(detections with at least MIN_CORNERS corners, image size (w, h), number of images) of a folder."""
    path = Path(folder)
    if not path.is_dir():
        raise ConfigError(option, str(path), "is not a folder")
    files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise ConfigError(option, str(path), f"holds no images ({', '.join(IMAGE_SUFFIXES)})")
    views: list[Detection] = []
    size: tuple[int, int] | None = None
    for file in files:
        image = cv2.imread(str(check_input_file(file, option, MAX_BINARY_BYTES, "image")), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise ConfigError(option, str(file), "is not a readable image")
        shape = (image.shape[1], image.shape[0])
        if size is not None and shape != size:
            raise ConfigError(option, str(file), f"is {shape[0]}x{shape[1]} px, the others {size[0]}x{size[1]}")
        size = shape
        found = detect(board, to_8bit(image), file.name)
        if found.ids.size >= MIN_CORNERS:
            views.append(found)
    assert size is not None  # files is not empty
    return views, size, len(files)


def _require(views, total, needed, option, folder):
    if len(views) < needed:
        raise UwlabError(
            f"{option} {folder}: only {len(views)} of {total} images show at least {MIN_CORNERS} "
            f"ChArUco corners of the board; need {needed} (check the board file, focus and lighting)"
        )


@dataclass(frozen=True)
class AirCalibration:
    lens: BrownLens
    rms_px: float
    views: int
    corners: int


def calibrate_air(board: CharucoBoard, views: list[Detection], size: tuple[int, int]) -> AirCalibration:
    """The lens (intrinsics, k1 k2 p1 p2) from views in air: OpenCV `calibrateCamera`."""
    objects = [board.corners_m[v.ids].astype(np.float32) for v in views]
    images = [v.pixels.astype(np.float32) for v in views]
    rms, matrix, dist, _, _ = cv2.calibrateCamera(objects, images, size, None, None, flags=cv2.CALIB_FIX_K3)
    return AirCalibration(BrownLens.from_opencv(matrix, dist), float(rms), len(views), sum(v.ids.size for v in views))


@dataclass
class PortFit:
    """The jointly refined lens and port: port parameters and standard deviations (PORT_PARAMETERS order), the
    water-side focal scale s, the focal ratio f_uw/f_air, RMS reprojection errors in water and air."""

    kind: str
    lens: BrownLens
    values: np.ndarray
    stds: np.ndarray
    scale: float
    scale_std: float
    f_ratio: float
    f_ratio_std: float
    rms_px: float
    air_rms_px: float
    corners: int
    outliers: int
    port: Port
    residuals_px: np.ndarray = field(repr=False)


def _port_mismatch(kind: str) -> ConfigError:
    return ConfigError("--port", kind, "does not match housing.port of the config")


def _make_port(kind: str, nominal: Port, p: np.ndarray) -> Port:
    if kind == "dome":
        if not isinstance(nominal, DomePort):
            raise _port_mismatch(kind)
        return DomePort(
            nominal.outer_radius_m,
            nominal.thickness_m,
            nominal.glass_index,
            nominal.water_index,
            (float(p[0]) * 1e-3, float(p[1]) * 1e-3, float(p[2]) * 1e-3),
        )
    if not isinstance(nominal, FlatPort):
        raise _port_mismatch(kind)
    return FlatPort(
        nominal.thickness_m,
        float(p[0]) * 1e-3,
        nominal.glass_index,
        nominal.water_index,
        (math.radians(p[1]), math.radians(p[2])),
    )


def _initial_port(kind: str, nominal: Port) -> np.ndarray:
    if kind == "dome":
        if not isinstance(nominal, DomePort):
            raise _port_mismatch(kind)
        return np.asarray(nominal.decenter_m, float) * 1e3
    if not isinstance(nominal, FlatPort):
        raise _port_mismatch(kind)
    return np.array([nominal.air_gap_m * 1e3, *np.degrees(nominal.tilt_rad)])


def _scaled(lens: BrownLens, s: float) -> BrownLens:
    return BrownLens(lens.fx * s, lens.fy * s, lens.cx, lens.cy, lens.distortion)


N_LENS = 8  # fx, fy, cx, cy, k1, k2, p1, p2 (k3 = 0)


def _lens_vector(lens: BrownLens) -> np.ndarray:
    return np.array([lens.fx, lens.fy, lens.cx, lens.cy, *lens.distortion[:4]])


def _lens_from(v) -> BrownLens:
    return BrownLens(v[0], v[1], v[2], v[3], (v[4], v[5], v[6], v[7], 0.0))


class _Problem:
    """Pixel residuals of all views as a function of x = [lens (8), port, log s, (rvec, tvec) per view]: views
    in air are traced through the port in air (index 1), views in water through it in water."""

    def __init__(self, kind, nominal, board, air_views, water_views, free_scale):
        self.kind, self.nominal, self.free_scale = kind, nominal, free_scale
        self.n_port = len(PORT_PARAMETERS[kind])
        views = [*air_views, *water_views]
        self.objects = np.concatenate([board.corners_m[v.ids] for v in views])
        self.observed = np.concatenate([v.pixels for v in views])
        self.view_of = np.concatenate([np.full(v.ids.size, i) for i, v in enumerate(views)])
        self.in_water = self.view_of >= len(air_views)
        self.n_views = len(views)
        self.n_global = N_LENS + self.n_port + 1

    def split(self, x):
        lens = _lens_from(x[:N_LENS])
        port = _make_port(self.kind, self.nominal, x[N_LENS : N_LENS + self.n_port])
        s = math.exp(x[self.n_global - 1]) if self.free_scale else 1.0
        return lens, port, s, x[self.n_global :].reshape(self.n_views, 6)

    def residuals(self, x, mask):
        lens, port, s, poses = self.split(x)
        views = self.view_of[mask]
        rotations = Rotation.from_rotvec(poses[:, :3]).as_matrix()[views]
        points = np.einsum("nij,nj->ni", rotations, self.objects[mask]) + poses[views, 3:]
        water = self.in_water[mask]
        pixels = np.empty((points.shape[0], 2))
        pixels[~water] = lens.pixels(port.in_medium(1.0).project(points[~water]))
        pixels[water] = _scaled(lens, s).pixels(port.project(points[water]))
        return (pixels - self.observed[mask]).ravel()

    def jacobian(self, x, mask):
        """Dense Jacobian of `residuals` by central differences, grouping each pose coordinate of all views in one
        evaluation (views touch disjoint residuals)."""
        n = x.size
        free_globals = [i for i in range(self.n_global) if self.free_scale or i != self.n_global - 1]
        columns = [np.array([i]) for i in free_globals]
        columns += [self.n_global + 6 * np.arange(self.n_views) + k for k in range(6)]
        steps = 1e-6 * np.maximum(np.abs(x), 1e-1)
        views = self.view_of[mask]
        rows_view = np.repeat(views, 2)
        jac = np.zeros((2 * int(mask.sum()), n))
        for group in columns:
            dx = np.zeros(n)
            dx[group] = steps[group]
            diff = self.residuals(x + dx, mask) - self.residuals(x - dx, mask)
            if group.size == 1:
                jac[:, group[0]] = diff / (2 * steps[group[0]])
            else:
                owner = self.n_global + 6 * rows_view + (group[0] - self.n_global)
                jac[np.arange(jac.shape[0]), owner] = diff / (2 * steps[owner])
        return jac


def _initial_poses(board, views, lens: BrownLens, ratio: float) -> np.ndarray:
    """Each view's pose from `solvePnP` with the lens's focal length scaled by the port's paraxial ratio."""
    matrix = _scaled(lens, ratio).camera_matrix
    poses = []
    for v in views:
        ok, rvec, tvec = cv2.solvePnP(board.corners_m[v.ids], v.pixels, matrix, np.asarray(lens.distortion))
        if not ok:
            raise UwlabError(f"{v.image}: no initial pose for the board")
        poses.append(np.r_[rvec.ravel(), tvec.ravel()])
    return np.concatenate(poses)


def fit_port(
    kind: str,
    nominal: Port,
    air: BrownLens,
    board: CharucoBoard,
    air_views: list[Detection],
    water_views: list[Detection],
    free_scale: bool = False,
) -> PortFit:
    """Refine lens, port, focal scale (when `free_scale`) and poses jointly on all views (module docstring)."""
    problem = _Problem(kind, nominal, board, air_views, water_views, free_scale)
    x0 = np.r_[
        _lens_vector(air),
        _initial_port(kind, nominal),
        0.0,
        _initial_poses(board, air_views, air, 1.0),
        _initial_poses(board, water_views, air, focal_ratio(nominal)),
    ]
    mask = np.ones(problem.observed.shape[0], bool)
    result, errors = _solve(problem, x0, mask)
    outliers = errors > OUTLIER_SIGMA * _rms(errors)
    if outliers.any():
        mask[np.flatnonzero(mask)[outliers]] = False
        result, errors = _solve(problem, result.x, mask)
    free = np.ones(result.x.size, bool)
    free[problem.n_global - 1] = free_scale
    jac = result.jac[:, free]
    sigma2 = float(result.fun @ result.fun) / max(jac.shape[0] - jac.shape[1], 1)
    cov = np.zeros((result.x.size, result.x.size))
    cov[np.ix_(free, free)] = np.linalg.pinv(jac.T @ jac) * sigma2
    lens, port, s, _ = problem.split(result.x)
    block = slice(N_LENS, problem.n_global)
    grad = _ratio_gradient(kind, nominal, result.x[block])
    water = problem.in_water[mask]
    return PortFit(
        kind,
        lens,
        result.x[N_LENS : N_LENS + problem.n_port],
        np.sqrt(np.diag(cov)[N_LENS : N_LENS + problem.n_port]),
        s,
        s * math.sqrt(cov[problem.n_global - 1, problem.n_global - 1]),
        s * focal_ratio(port),
        float(math.sqrt(max(grad @ cov[block, block] @ grad, 0.0))),
        _rms(errors[water]),
        _rms(errors[~water]),
        int(water.sum()),
        int((~mask).sum()),
        port,
        result.fun.reshape(-1, 2),
    )


def _solve(problem: _Problem, x0, mask):
    """Levenberg–Marquardt on the corners in `mask`; (result, per-corner error [px])."""
    result = least_squares(
        problem.residuals,
        x0,
        jac=problem.jacobian,
        method="lm",
        x_scale="jac",
        ftol=1e-12,
        xtol=1e-12,
        gtol=1e-12,
        max_nfev=200,
        args=(mask,),
    )
    if not np.all(np.isfinite(result.fun)):
        raise UwlabError("the port fit left the valid region (rays missing the port); check --port and the config")
    return result, np.linalg.norm(result.fun.reshape(-1, 2), axis=1)


def _rms(errors) -> float:
    return float(np.sqrt(np.mean(np.asarray(errors) ** 2)))


def _ratio_gradient(kind, nominal, p, step=1e-4):
    """∂(s · focal_ratio(port)) / ∂(port parameters, log s) by central differences."""

    def ratio(q):
        return math.exp(q[-1]) * focal_ratio(_make_port(kind, nominal, q[:-1]))

    grad = np.zeros(p.size)
    for i in range(p.size):
        dp = np.zeros(p.size)
        dp[i] = step
        grad[i] = (ratio(p + dp) - ratio(p - dp)) / (2 * step)
    return grad


def induced_distortion_px(port: Port, lens: BrownLens, size: tuple[int, int]) -> float:
    """Largest |radial distortion| the port adds at the image corners [px] (objects at infinity)."""
    width, height = size
    corners = np.array([[0.0, 0.0], [width - 1.0, 0.0], [0.0, height - 1.0], [width - 1.0, height - 1.0]])
    slopes = (corners - [lens.cx, lens.cy]) / [lens.fx, lens.fy]
    _, shift = port_distortion(port, slopes, 1.0)
    return float(np.max(np.abs(shift)) * lens.fx)


class WaterViews(TypedDict):
    """The views in water: images read, views with enough corners, corners fitted and outliers dropped."""

    images: int
    views: int
    corners: int
    outliers: int


class AirViews(TypedDict):
    """The views in air and the lens refined on all views (OpenCV's RMS: step 2's, before the joint fit)."""

    images: int
    views: int
    corners: int
    rms_px: float
    opencv_rms_px: float
    focal_length_px: list[float]
    principal_point_px: list[float]
    distortion: list[float]


class FocusAndViews(TypedDict):
    """The last keys of `PortCalibration`: the focus and the views of both sets."""

    focus: str
    focal_scale: float
    focal_scale_std: float | None
    water: WaterViews
    air: AirViews
    image_size_px: list[int]


class PortCalibration(FocusAndViews):
    """The result record of `calibrate_port` (the keys of `uwlab port calibrate`): the port, the focal ratio and the
    RMS error in water, then `FocusAndViews`; the decentring and its verdict only for a dome, the port distance and
    tilts only for a flat port."""

    port: str
    decenter_mm: NotRequired[dict[str, float]]
    decenter_mm_std: NotRequired[dict[str, float]]
    port_distance_mm: NotRequired[float]
    port_distance_mm_std: NotRequired[float]
    tilt_deg: NotRequired[dict[str, float]]
    tilt_deg_std: NotRequired[dict[str, float]]
    f_ratio: float
    f_ratio_std: float
    rms_px: float
    centred_enough: NotRequired[bool]
    induced_distortion_px: NotRequired[float]
    max_distortion_px: NotRequired[float]


def calibrate_port(
    board: CharucoBoard,
    air_dir,
    water_dir,
    kind: str,
    nominal: Port,
    refocused: bool = False,
    max_distortion_px: float = DEFAULT_MAX_DISTORTION_PX,
) -> PortCalibration:
    """The whole procedure (module docstring); returns the result record (the keys of `uwlab port calibrate`)."""
    if kind not in PORT_PARAMETERS:
        raise ConfigError("--port", kind, "must be flat or dome")
    if kind == "dome" and not isinstance(nominal, DomePort) or kind == "flat" and not isinstance(nominal, FlatPort):
        raise _port_mismatch(kind)
    air_views, air_size, air_total = read_views(board, air_dir, "DIR_AIR")
    _require(air_views, air_total, MIN_AIR_VIEWS, "DIR_AIR", air_dir)
    water_views, water_size, water_total = read_views(board, water_dir, "DIR_WATER")
    _require(water_views, water_total, MIN_WATER_VIEWS, "DIR_WATER", water_dir)
    if water_size != air_size:
        raise ConfigError(
            "DIR_WATER",
            str(water_dir),
            f"images are {water_size[0]}x{water_size[1]} px, those in air {air_size[0]}x{air_size[1]}",
        )
    air = calibrate_air(board, air_views, air_size)
    fit = fit_port(kind, nominal, air.lens, board, air_views, water_views, free_scale=refocused)
    tail: FocusAndViews = {
        "focus": "refocused" if refocused else "locked",
        "focal_scale": fit.scale,
        "focal_scale_std": fit.scale_std if refocused else None,
        "water": {
            "images": water_total,
            "views": len(water_views),
            "corners": fit.corners,
            "outliers": fit.outliers,
        },
        "air": {
            "images": air_total,
            "views": air.views,
            "corners": air.corners,
            "rms_px": fit.air_rms_px,
            "opencv_rms_px": air.rms_px,
            "focal_length_px": [fit.lens.fx, fit.lens.fy],
            "principal_point_px": [fit.lens.cx, fit.lens.cy],
            "distortion": list(fit.lens.distortion),
        },
        "image_size_px": list(air_size),
    }
    if kind == "dome":
        distortion = induced_distortion_px(fit.port, _scaled(fit.lens, fit.scale), air_size)
        return {
            "port": kind,
            "decenter_mm": dict(zip("xyz", fit.values, strict=True)),
            "decenter_mm_std": dict(zip("xyz", fit.stds, strict=True)),
            "f_ratio": fit.f_ratio,
            "f_ratio_std": fit.f_ratio_std,
            "rms_px": fit.rms_px,
            "centred_enough": bool(distortion <= max_distortion_px),
            "induced_distortion_px": distortion,
            "max_distortion_px": max_distortion_px,
            **tail,
        }
    return {
        "port": kind,
        "port_distance_mm": fit.values[0],
        "port_distance_mm_std": fit.stds[0],
        "tilt_deg": dict(zip("xy", fit.values[1:], strict=True)),
        "tilt_deg_std": dict(zip("xy", fit.stds[1:], strict=True)),
        "f_ratio": fit.f_ratio,
        "f_ratio_std": fit.f_ratio_std,
        "rms_px": fit.rms_px,
        **tail,
    }
