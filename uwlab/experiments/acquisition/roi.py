"""Regions of interest of a sweep: a rectangle, or the interior of a target board marked with ArUco markers.

ArUco detection uses OpenCV's `cv2.aruco.ArucoDetector` (OpenCV ≥ 4.7, contrib "aruco" module; Garrido-Jurado
et al., "Automatic generation and detection of highly reliable fiducial markers under occlusion", Pattern
Recognition 47(6), 2014). Convention: the markers sit at the board's edges (e.g. its corners); the board's
interior is the bounding box of all detected marker corners shrunk on every side by the largest marker side,
so no marker pixel (nor its quiet zone, up to one marker side) lies inside the ROI.
"""

from __future__ import annotations

import numpy as np

from uwlab.errors import ConfigError, DeviceError

Rect = tuple[int, int, int, int]
MIN_MARKERS = 2


def check_inside(key: str, roi: Rect, shape_yx: tuple[int, int]) -> Rect:
    """``roi`` (x, y, w, h) if it lies within an image of ``shape_yx``, else `ConfigError` on ``key``."""
    x, y, w, h = roi
    height, width = shape_yx
    if x < 0 or y < 0 or w < 2 or h < 2 or x + w > width or y + h > height:
        raise ConfigError(key, list(roi), f"must lie within the {width}x{height} image")
    return roi


def to_uint8(image: np.ndarray) -> np.ndarray:
    """An 8-bit view for detection: the image stretched between its 1st and 99th percentiles."""
    lo, hi = np.percentile(image, (1.0, 99.0))
    scaled = (image.astype(np.float32) - lo) / max(float(hi - lo), 1e-6)
    return (np.clip(scaled, 0.0, 1.0) * 255.0).astype(np.uint8)


def detect_markers(image: np.ndarray, dictionary: str = "DICT_4X4_50") -> tuple[np.ndarray, np.ndarray]:
    """(corners (n, 4, 2) float, ids (n,)) of the ArUco markers found in a grey image."""
    import cv2

    detector = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)), cv2.aruco.DetectorParameters()
    )
    corners, ids, _ = detector.detectMarkers(to_uint8(image))
    if ids is None:
        return np.empty((0, 4, 2)), np.empty(0, int)
    return np.asarray(corners, float).reshape(-1, 4, 2), ids.reshape(-1)


def interior_roi(corners: np.ndarray) -> Rect:
    """The board interior (x, y, w, h) from marker corners (n, 4, 2) — see the module docstring."""
    if len(corners) < MIN_MARKERS:
        raise DeviceError(f"ArUco ROI: found {len(corners)} marker(s), need at least {MIN_MARKERS}")
    sides = np.linalg.norm(np.roll(corners, -1, axis=1) - corners, axis=2)
    margin = float(sides.max())
    points = corners.reshape(-1, 2)
    x0, y0 = points.min(axis=0) + margin
    x1, y1 = points.max(axis=0) - margin
    if x1 - x0 < 2 or y1 - y0 < 2:
        raise DeviceError("ArUco ROI: the markers enclose no interior (are they at the board's edges?)")
    left, top = int(np.ceil(x0)), int(np.ceil(y0))
    return left, top, int(np.floor(x1)) - left, int(np.floor(y1)) - top


def aruco_roi(image: np.ndarray, dictionary: str = "DICT_4X4_50") -> Rect:
    """The interior of the ArUco-marked board seen in ``image``."""
    corners, _ = detect_markers(image, dictionary)
    return interior_roi(corners)
