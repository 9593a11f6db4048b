"""Exact refraction through housing ports: vectorised ray tracing from the entrance pupil into the water.

Conventions: camera axes with the origin at the lens's entrance pupil (the centre of projection), x right, y down,
z forward along the optical axis (OpenCV's camera frame); lengths in metres, angles in radians. Rays are arrays of
points and unit directions of shape (..., 3). A port is a sequence of refracting interfaces between air (index 1),
the port material and the outside medium (water, or air for a housing in air).

- Snell's law in vector form (Hecht, Optics, 5th ed., §4.4; the vector form as in Glassner, An Introduction to
  Ray Tracing, 1989, §6): for a unit direction d meeting a surface with unit normal m facing the incoming ray
  (m·d < 0), η = n₁/n₂ and cos θᵢ = −m·d, the refracted direction is t = η d + (η cos θᵢ − √k) m with
  k = 1 − η² (1 − cos² θᵢ); k < 0 is total internal reflection (the ray is flagged and its values are NaN).
- Flat port (Treibitz, Schechner, Kunz & Singh, "Flat refractive geometry", IEEE PAMI 34(1), 2012; Agrawal,
  Ramalingam, Taguchi & Chari, "A theory of multi-layer flat refractive geometry", CVPR 2012): two parallel
  planes with unit normal m, the inner face at perpendicular distance `air_gap` from the pupil (m·x = gap) and
  the outer at gap + thickness. The normal is tilted from the optical axis by the angles (tilt_x, tilt_y) that
  it makes with the axis in the x–z and y–z planes: m ∝ (tan tilt_x, tan tilt_y, 1).
- Dome port (Kunz & Singh, "Hemispherical refraction and camera calibration in underwater vision", OCEANS
  2008): two concentric spheres of radii R_o (outer) and R_i = R_o − thickness. `decenter` is the position of
  the entrance pupil relative to the spheres' common centre, in camera axes (z > 0: the pupil sits in front of
  the centre, towards the dome). A centred pupil sends every ray along a normal: no refraction.

Projection (scene point in water → camera ray) has no closed form for a tilted or decentred port (a flat port
gives a 12th-degree polynomial even untilted, Agrawal et al. 2012); `Port.project` solves it by Gauss–Newton
on the ray's slope (x/z, y/z) in air.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from uwlab.errors import ConfigError

AIR_INDEX = 1.0
_PROJECT_STEP = 1e-7


def normalize(v):
    """Unit vectors along the last axis."""
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def refract(d, m, n1, n2):
    """(t, tir): refracted unit directions of unit directions d at a surface of unit normal m (either
    orientation) from index n1 into n2, and the total-internal-reflection mask (t is NaN there)."""
    d, m = np.asarray(d, float), np.asarray(m, float)
    cos_i = -np.sum(m * d, axis=-1, keepdims=True)
    m = np.where(cos_i < 0, -m, m)
    cos_i = np.abs(cos_i)
    eta = np.asarray(n1, float) / np.asarray(n2, float)
    k = 1.0 - eta**2 * (1.0 - cos_i**2)
    tir = k[..., 0] < 0
    with np.errstate(invalid="ignore"):
        t = eta * d + (eta * cos_i - np.sqrt(k)) * m
    return t, tir


@dataclass(frozen=True)
class Plane:
    """The plane m·x = offset (m a unit normal). A one-sided plane is met only ahead of the ray (s ≥ 0; a ray
    starting on it meets it at s = 0: a window of zero thickness); a two-sided one anywhere on the ray's line,
    which continues a flat port smoothly through an air gap of zero (for fits that cross it)."""

    normal: tuple[float, float, float]
    offset: float
    one_sided: bool = True

    def intersect(self, p, d):
        """(distance along d, unit normal at the hit) for rays p + s d; NaN for rays parallel to the plane, and
        for rays going away from a one-sided plane."""
        m = np.asarray(self.normal, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (self.offset - p @ m) / (d @ m)
        s = np.where((s >= 0) | (not self.one_sided) & np.isfinite(s), s, np.nan)
        return s, np.broadcast_to(m, np.shape(p))


@dataclass(frozen=True)
class Sphere:
    """The sphere |x − centre| = radius; rays start inside it and leave through it."""

    centre: tuple[float, float, float]
    radius: float

    def intersect(self, p, d):
        c = np.asarray(self.centre, float)
        oc = p - c
        b = np.sum(d * oc, axis=-1)
        disc = b**2 - (np.sum(oc * oc, axis=-1) - self.radius**2)
        with np.errstate(invalid="ignore"):
            s = -b + np.sqrt(disc)
        s = np.where(s > 0, s, np.nan)
        hit = p + s[..., None] * d
        return s, (hit - c) / self.radius


@dataclass(frozen=True)
class Rays:
    """Rays leaving the port: points on its outer surface, unit directions outside, and a validity mask
    (False where a ray missed a surface or was totally reflected)."""

    points: np.ndarray
    directions: np.ndarray
    valid: np.ndarray

    def at_plane(self, normal, offset):
        """Where the rays meet the plane normal·x = offset (NaN where they do not)."""
        s, _ = Plane(tuple(normal), float(offset)).intersect(self.points, self.directions)
        return self.points + s[..., None] * self.directions


class Port:
    """A sequence of refracting interfaces (surface, index after it) from the air inside the housing outwards."""

    water_index: float

    def interfaces(self) -> list[tuple[Plane | Sphere, float]]:
        raise NotImplementedError

    def in_medium(self, index: float) -> Port:
        """The same port with another outside medium (index 1 for the housing in air)."""
        return replace(self, water_index=float(index))

    def trace(self, directions, origins=(0.0, 0.0, 0.0)) -> Rays:
        """Trace rays leaving the camera (points `origins`, default the pupil, unit `directions`) into the water."""
        d = normalize(directions)
        p = np.broadcast_to(np.asarray(origins, float), d.shape).copy()
        valid = np.ones(d.shape[:-1], bool)
        n_before = AIR_INDEX
        for surface, n_after in self.interfaces():
            s, m = surface.intersect(p, d)
            p = p + s[..., None] * d
            d, tir = refract(d, m, n_before, n_after)
            valid &= np.isfinite(s) & ~tir
            n_before = n_after
        return Rays(p, d, valid)

    def project(self, points, origins=(0.0, 0.0, 0.0), iterations=30, tol=1e-13):
        """Unit camera-side directions whose rays from `origins` reach the scene `points` (..., 3) through the
        port (Gauss–Newton on the slopes a = x/z, b = y/z; NaN where it does not converge)."""
        q = np.asarray(points, float)
        o = np.broadcast_to(np.asarray(origins, float), q.shape)
        ab = (q[..., :2] - o[..., :2]) / (q[..., 2:] - o[..., 2:])
        done = np.zeros(q.shape[:-1], bool)
        for _ in range(iterations):
            e0 = self._miss(ab, q, o)
            jac = np.stack(
                [
                    (self._miss(ab + step, q, o) - e0) / _PROJECT_STEP
                    for step in (np.array([_PROJECT_STEP, 0.0]), np.array([0.0, _PROJECT_STEP]))
                ],
                axis=-1,
            )
            jtj = np.swapaxes(jac, -1, -2) @ jac
            jte = np.swapaxes(jac, -1, -2) @ e0[..., None]
            with np.errstate(invalid="ignore"):
                delta = -np.linalg.solve(jtj + 1e-30 * np.eye(2), jte)[..., 0]
            delta = np.where(done[..., None], 0.0, delta)
            ab = ab + delta
            done |= np.max(np.abs(delta), axis=-1) < tol
            if done.all():
                break
        ok = done & np.all(np.isfinite(ab), axis=-1)
        d = normalize(np.concatenate([ab, np.ones(ab.shape[:-1] + (1,))], axis=-1))
        return np.where(ok[..., None], d, np.nan)

    def _miss(self, ab, q, o):
        """How far the ray of slopes ab misses q: unit(q − exit point) − exit direction (zero on a hit)."""
        d = np.concatenate([ab, np.ones(ab.shape[:-1] + (1,))], axis=-1)
        rays = self.trace(d, o)
        return normalize(q - rays.points) - rays.directions


@dataclass(frozen=True)
class FlatPort(Port):
    """A plane-parallel window: thickness, air gap (pupil → inner face, along the normal), tilt of its normal."""

    thickness_m: float
    air_gap_m: float
    glass_index: float
    water_index: float
    tilt_rad: tuple[float, float] = (0.0, 0.0)

    @property
    def normal(self) -> np.ndarray:
        return normalize([np.tan(self.tilt_rad[0]), np.tan(self.tilt_rad[1]), 1.0])

    def interfaces(self):
        m = tuple(self.normal)
        return [
            (Plane(m, self.air_gap_m, one_sided=False), self.glass_index),
            (Plane(m, self.air_gap_m + self.thickness_m, one_sided=False), self.water_index),
        ]


@dataclass(frozen=True)
class DomePort(Port):
    """A spherical shell: outer radius, thickness, and the pupil's offset from the centre of curvature."""

    outer_radius_m: float
    thickness_m: float
    glass_index: float
    water_index: float
    decenter_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def interfaces(self):
        centre = tuple(-np.asarray(self.decenter_m, float))
        return [
            (Sphere(centre, self.outer_radius_m - self.thickness_m), self.glass_index),
            (Sphere(centre, self.outer_radius_m), self.water_index),
        ]


def port_from_housing(values: dict) -> Port:
    """The exact port of a design's [housing] values (single values: a ray trace has one port)."""
    for key in (
        "water_index",
        "port_index",
        "flat_thickness_mm",
        "flat_air_gap_mm",
        "dome_radius_mm",
        "dome_thickness_mm",
    ):
        if np.ndim(values[key]) > 0:
            raise ConfigError(
                f"housing.{key}", np.asarray(values[key]).tolist(), "must be a single value to trace rays"
            )
    n_w, n_p = float(values["water_index"]), float(values["port_index"])
    if values["port"] == "dome":
        return DomePort(
            values["dome_radius_mm"] * 1e-3,
            values["dome_thickness_mm"] * 1e-3,
            n_p,
            n_w,
            tuple(v * 1e-3 for v in values["dome_decenter_mm"]),
        )
    return FlatPort(
        values["flat_thickness_mm"] * 1e-3,
        values["flat_air_gap_mm"] * 1e-3,
        n_p,
        n_w,
        tuple(np.radians(values["flat_tilt_deg"])),
    )
