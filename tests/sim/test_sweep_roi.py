"""ArUco ROI on a synthetic board generated with cv2.aruco, and rectangle checks."""

import cv2
import numpy as np
import pytest

from uwlab.errors import ConfigError, DeviceError
from uwlab.experiments.acquisition.roi import aruco_roi, check_inside


def board_image(marker_px=40, origin=(60, 50), size=(300, 200), dtype=np.uint16):
    """A dark scene with a bright board whose corners carry ArUco markers 0-3 (4x4_50), in 12-bit DN."""
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    image = np.full((360, 480), 300.0)
    x0, y0 = origin
    w, h = size
    image[y0 : y0 + h, x0 : x0 + w] = 3500.0
    quiet = 10
    corners = [
        (x0 + quiet, y0 + quiet),
        (x0 + w - quiet - marker_px, y0 + quiet),
        (x0 + quiet, y0 + h - quiet - marker_px),
        (x0 + w - quiet - marker_px, y0 + h - quiet - marker_px),
    ]
    for marker_id, (cx, cy) in enumerate(corners):
        marker = cv2.aruco.generateImageMarker(dictionary, marker_id, marker_px)
        image[cy : cy + marker_px, cx : cx + marker_px] = np.where(marker > 0, 3500.0, 300.0)
    noise = np.random.default_rng(1).normal(0.0, 20.0, image.shape)
    return (image + noise).astype(dtype)


def test_aruco_roi_is_the_board_interior_between_the_markers():
    x, y, w, h = aruco_roi(board_image())
    # markers span x 70..110 and 310..350 (board 60..360): interior = corner bbox shrunk by one marker side
    assert (x, y) == pytest.approx((110, 100), abs=2)
    assert (x + w, y + h) == pytest.approx((310, 200), abs=2)


def test_aruco_roi_follows_the_board():
    x0, y0, _, _ = aruco_roi(board_image())
    x1, y1, _, _ = aruco_roi(board_image(origin=(120, 100)))
    assert (x1 - x0, y1 - y0) == pytest.approx((60, 50), abs=1)


def test_no_markers_is_a_clear_error():
    with pytest.raises(DeviceError, match="found 0 marker"):
        aruco_roi(np.full((100, 100), 1000, np.uint16))


def test_rectangles_must_lie_inside_the_image():
    assert check_inside("roi", (2, 3, 10, 10), (20, 20)) == (2, 3, 10, 10)
    with pytest.raises(ConfigError, match="within the 20x20 image"):
        check_inside("roi", (15, 0, 10, 10), (20, 20))
