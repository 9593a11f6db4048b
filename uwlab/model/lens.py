"""The lens as a camera model: pinhole intrinsics with Brown–Conrady distortion, in OpenCV's convention.

Conventions: camera axes of `uwlab.model.raytrace` (x right, y down, z forward); pixel coordinates with the
centre of the top-left pixel at (0, 0). A ray of direction (X, Y, Z) has normalised coordinates x = X/Z,
y = Y/Z; with r² = x² + y² the distorted coordinates are (Brown, "Decentering distortion of lenses",
Photogrammetric Engineering 32(3), 1966; the five-coefficient form of OpenCV's `calibrateCamera`):

    x' = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)
    y' = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y

and the pixel is (fx x' + cx, fy y' + cy). The inverse (pixel → ray) has no closed form: fixed-point iteration
x = (x' − tangential(x, y)) / radial(r²), as OpenCV's `undistortPoints`, run to convergence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uwlab.model.raytrace import normalize


@dataclass(frozen=True)
class BrownLens:
    """Intrinsics fx, fy, cx, cy [px] and distortion (k1, k2, p1, p2, k3)."""

    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    @classmethod
    def from_opencv(cls, camera_matrix, dist_coeffs) -> BrownLens:
        k = np.asarray(camera_matrix, float)
        dist = np.zeros(5)
        coeffs = np.asarray(dist_coeffs, float).ravel()[:5]
        dist[: coeffs.size] = coeffs
        return cls(k[0, 0], k[1, 1], k[0, 2], k[1, 2], tuple(dist))

    @property
    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def _distort(self, x, y):
        k1, k2, p1, p2, k3 = self.distortion
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        return x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x), y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y

    def pixels(self, directions):
        """Pixel coordinates (..., 2) of rays of the given directions (..., 3) through the pupil."""
        d = np.asarray(directions, float)
        xd, yd = self._distort(d[..., 0] / d[..., 2], d[..., 1] / d[..., 2])
        return np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)

    def rays(self, pixels, iterations=100, tol=1e-14):
        """Unit directions (..., 3) of the rays of pixel coordinates (..., 2)."""
        p = np.asarray(pixels, float)
        xd = (p[..., 0] - self.cx) / self.fx
        yd = (p[..., 1] - self.cy) / self.fy
        k1, k2, p1, p2, k3 = self.distortion
        x, y = xd.copy(), yd.copy()
        for _ in range(iterations):
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            nx = (xd - 2 * p1 * x * y - p2 * (r2 + 2 * x * x)) / radial
            ny = (yd - p1 * (r2 + 2 * y * y) - 2 * p2 * x * y) / radial
            step = max(float(np.max(np.abs(nx - x), initial=0.0)), float(np.max(np.abs(ny - y), initial=0.0)))
            x, y = nx, ny
            if step < tol:
                break
        return normalize(np.stack([x, y, np.ones_like(x)], axis=-1))
