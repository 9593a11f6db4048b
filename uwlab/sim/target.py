"""What the simulated camera sees of a flat printed target (a calibration board) through its housing port.

Rendering by inverse mapping, so that every feature lies exactly where the optics put it: the rays of the pixel
corners go from the lens model (`uwlab.model.lens.BrownLens`, pixel → ray) through the port
(`uwlab.model.raytrace`, exact refraction) into the medium, once per camera; for each pose of the target they
meet its plane, giving target coordinates at the pixel corners. Each pixel is then the mean of s × s samples of
the target's reflectance (bilinear in a texture finer than the samples) at points interpolated bilinearly
between its corners (the mapping is smooth on the scale of a pixel; OpenCV's `remap` interpolates on a 1/32 grid,
which holds the s × s sample positions exactly for s = 2, 4, 8): an anti-aliased box filter over the pixel.
Illumination is uniform (no vignetting, no attenuation) and there is no defocus blur: the images test geometry.

Pose convention (OpenCV's): a target point X (target frame) is at R X + t in camera axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from uwlab.model.lens import BrownLens
from uwlab.model.raytrace import Port, Rays

OFF_TARGET = -1.0e6  # texel coordinate of rays that miss the target plane (sampled as background)


@dataclass(frozen=True)
class PlanarTarget:
    """A reflectance texture (float32) on the plane z = 0 of the target frame: `texel_m` per texel, the texture's
    outer top-left corner at target coordinates `origin_m`, `background` reflectance outside it."""

    reflectance: np.ndarray
    texel_m: float
    origin_m: tuple[float, float]
    background: float

    def __post_init__(self):
        object.__setattr__(self, "reflectance", np.ascontiguousarray(self.reflectance, np.float32))


class TargetView:
    """A camera (lens, resolution, port in its medium) looking at planar targets."""

    def __init__(self, lens: BrownLens, resolution_px: tuple[int, int], port: Port, supersample: int = 4):
        self.lens = lens
        self.width, self.height = resolution_px
        self.supersample = supersample
        u, v = np.meshgrid(np.arange(self.width + 1) - 0.5, np.arange(self.height + 1) - 0.5)
        self._rays: Rays = port.trace(lens.rays(np.stack([u, v], axis=-1)))
        self._maps = None

    def target_coordinates(self, rotation, translation) -> np.ndarray:
        """Target-frame (x, y) [m] where the pixel-corner rays meet the target plane, (height+1, width+1, 2)
        (NaN where a ray misses it or hits it from behind)."""
        r = np.asarray(rotation, float)
        t = np.asarray(translation, float).ravel()
        normal = r[:, 2]
        hits = self._rays.at_plane(normal, float(normal @ t))
        local = (hits - t) @ r
        return np.where(self._rays.valid[..., None], local[..., :2], np.nan)

    def reflectance_image(self, target: PlanarTarget, rotation, translation) -> np.ndarray:
        """Mean target reflectance over each pixel, (height, width) float32."""
        corners = self.target_coordinates(rotation, translation)
        texel = (corners - np.asarray(target.origin_m)) / target.texel_m - 0.5
        texel = np.where(np.isfinite(texel), texel, OFF_TARGET).astype(np.float32)
        map_x, map_y = self._sample_maps()
        u = cv2.remap(texel[..., 0], map_x, map_y, cv2.INTER_LINEAR)
        v = cv2.remap(texel[..., 1], map_x, map_y, cv2.INTER_LINEAR)
        sampled = cv2.remap(
            target.reflectance,
            u,
            v,
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=float(target.background),
        )
        return cv2.resize(sampled, (self.width, self.height), interpolation=cv2.INTER_AREA)

    def _sample_maps(self):
        """Positions of the s × s sub-pixel samples in the pixel-corner grid (corner (i, j) at index (i, j))."""
        if self._maps is None:
            s = self.supersample
            x = ((np.arange(self.width * s) + 0.5) / s).astype(np.float32)
            y = ((np.arange(self.height * s) + 0.5) / s).astype(np.float32)
            self._maps = tuple(np.ascontiguousarray(m) for m in np.meshgrid(x, y))
        return self._maps
