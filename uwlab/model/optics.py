"""Lens geometry and image irradiance: field of view, depth of field, minimum aperture, lens irradiance factor.

Conventions: lengths in metres unless the name says otherwise; f-number N = f / D; angles in radians inside,
degrees only at the config/CLI boundary; the circle of confusion c is given on the sensor.

- Camera equation: E_s = L_a · T_lens · π / (4 N²) · cos⁴α for an object at a distance much larger than f
  (Slater, Remote Sensing: Optics and Optical Systems, 1980; EMVA 1288 Release 4.0 §3.1 uses the same).
- Depth of field from the hyperfocal distance H = f²/(N c) + f of a thin lens focused at s (in the lens's own
  medium, air): near = s (H − f) / (H + s − 2f), far = s (H − f) / (H − s) for s < H, else ∞
  (Ray, Applied Photographic Optics, 3rd ed., 2002, §6). For s ≫ f the total is the paper's approximation
  2 N c f² s² / (f⁴ − N² c² s²).
- Underwater the lens focuses on the port's virtual image (flat: s / n_w, or with the air gap and window
  thickness of `uwlab.model.port.flat_apparent_distance`; dome: see `uwlab.model.port`), so near/far are
  computed in image space and mapped back to object distances in water.
- No lens (a bare sensor): under a uniform Lambertian field of radiance L a sensor receives E = π L, which is
  the camera equation with N = 1/2 and T = 1 (the f-number limit of an aplanatic lens in air; e.g. Ohta,
  *Radiometry*). `LensSetting` carries this rule: a bare sensor is evaluated as a lens with
  `BARE_SENSOR_F_NUMBER` and `BARE_SENSOR_TRANSMITTANCE`, without vignetting.
- A bare sensor under a uniform Lambertian disk of radiance L, diameter D, at distance d (the EMVA 1288 bench,
  Release 4.0 Linear §6.1, f-number N = d/D, eq. 46): at a distance r from the axis on the sensor plane
  E = (π L / 2) [1 − (d² + r² − R²) / √((d² + r² + R²)² − 4 r² R²)], R = D/2 (the view factor from a differential
  area to a parallel coaxial disk; Howell, *A Catalog of Radiation Heat Transfer Configuration Factors*, B-13);
  on axis E = π L / (1 + 4 N²) (`disk_source_irradiance_factor`).
- The minimum f-number for a required depth of field D solves far − near = D. In air-equivalent space, with
  a = f²/(N c), the total is 2 s a (s − f) / (a² − (s − f)²), so a = (s − f)(s + √(s² + D²)) / D and
  N = f² / (c a). Dome ports have no closed form: bisection on log N.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uwlab.model import port as port_model


BARE_SENSOR_F_NUMBER = 0.5
BARE_SENSOR_TRANSMITTANCE = 1.0


@dataclass(frozen=True)
class LensSetting:
    """A lens on a camera at one aperture, or no lens at all (``focal_length_mm`` None: the bare sensor).

    ``f_number_range`` is the lens's aperture range [lo, hi] when known; ``manual`` says the aperture is set by
    hand (an operator has to turn the ring).

    >>> LensSetting(30.0, 2.0).label, NO_LENS.label
    ('30mm-F2.0', 'no-lens')
    >>> NO_LENS.overrides()
    {'lens.f_number': 0.5, 'lens.transmittance': 1.0}
    """

    focal_length_mm: float | None
    f_number: float | None
    f_number_range: tuple[float, float] | None = None
    manual: bool = True

    @property
    def bare(self) -> bool:
        return self.focal_length_mm is None

    @property
    def label(self) -> str:
        return "no-lens" if self.bare else f"{self.focal_length_mm:g}mm-F{self.f_number:.1f}"

    def overrides(self) -> dict[str, float]:
        """Design values (``section.key``) that put this lens on a design: the bare sensor's N and T, or the
        lens's focal length and f-number (its transmittance stays the design's)."""
        if self.bare:
            return {"lens.f_number": BARE_SENSOR_F_NUMBER, "lens.transmittance": BARE_SENSOR_TRANSMITTANCE}
        assert self.focal_length_mm is not None and self.f_number is not None  # a lens has both
        return {"lens.focal_length_mm": float(self.focal_length_mm), "lens.f_number": float(self.f_number)}


NO_LENS = LensSetting(None, None)


def lens_irradiance_factor(f_number, cos_alpha=1.0):
    """π / (4 N²) · cos⁴α: sensor irradiance per unit scene radiance behind the port (×T_lens)."""
    return np.pi / (4.0 * np.asarray(f_number, float) ** 2) * np.asarray(cos_alpha, float) ** 4


def disk_source_irradiance_factor(f_number, r_over_d=0.0):
    """E / L [sr] on a plane parallel to a Lambertian disk of f-number N = d/D, at r/d from its axis (module
    docstring); π / (1 + 4 N²) on axis.

    >>> round(float(disk_source_irradiance_factor(8.0)) * 257 / np.pi, 12)
    1.0
    """
    n = np.asarray(f_number, float)
    rho = np.asarray(r_over_d, float)
    radius = 1.0 / (2.0 * n)
    a = 1.0 + rho**2 + radius**2
    return 0.5 * np.pi * (1.0 - (1.0 + rho**2 - radius**2) / np.sqrt(a**2 - 4.0 * rho**2 * radius**2))


def angular_fov_rad(sensor_size_m, focal_length_m):
    """Full angular field of view 2·atan(size / 2f) along one sensor axis (pinhole, focus at infinity)."""
    return 2.0 * np.arctan(np.asarray(sensor_size_m, float) / (2.0 * np.asarray(focal_length_m, float)))


def spatial_fov_m(fov_rad, distance_m):
    """Footprint 2 d tan(fov / 2) on a plane perpendicular to the axis at distance d."""
    return 2.0 * np.asarray(distance_m, float) * np.tan(np.asarray(fov_rad, float) / 2.0)


def dof_in_air(s_m, focal_length_m, f_number, coc_m):
    """(near, far) limits of acceptable focus for a thin lens in air focused at s_m (far = inf past H); near = far =
    s_m where s_m ≤ f (an object within the focal length forms no real image: nothing is in focus)."""
    s = np.asarray(s_m, float)
    f = np.asarray(focal_length_m, float)
    a = f**2 / (np.asarray(f_number, float) * np.asarray(coc_m, float))
    focusable = s > f
    near = np.where(focusable, s * a / (a + s - f), s)
    with np.errstate(divide="ignore"):
        far = np.where(focusable, np.where(a + f - s > 0, s * a / (a + f - s), np.inf), s)
    return near, far


def dof_underwater(s_m, focal_length_m, f_number, coc_m, port, water_index, dome=None, flat=(0.0, 0.0, 1.0)):
    """(near, far) object distances in water for a lens focused on the object at s_m behind `port`.

    port: "flat" or "dome"; dome = (radius_m, thickness_m, port_index) for a dome port; flat = (air_gap_m,
    thickness_m, port_index) for a flat port (default: a thin window at the pupil).
    """
    if port == "dome":
        radius_m, thickness_m, port_index = dome
        v = port_model.dome_virtual_distance(s_m, radius_m, thickness_m, water_index, port_index)
        v_near, v_far = dof_in_air(v, focal_length_m, f_number, coc_m)
        near = port_model.dome_object_distance(v_near, radius_m, thickness_m, water_index, port_index)
        far = port_model.dome_object_distance(v_far, radius_m, thickness_m, water_index, port_index)
        return near, far
    near, far = dof_in_air(port_model.flat_apparent_distance(s_m, water_index, *flat), focal_length_m, f_number, coc_m)
    return (
        port_model.flat_object_distance(near, water_index, *flat),
        port_model.flat_object_distance(far, water_index, *flat),
    )


def min_f_number_in_air(s_m, focal_length_m, coc_m, dof_m):
    """Smallest N giving a total depth of field dof_m for a thin lens in air focused at s_m (closed form); inf
    where s_m ≤ f: an object within the focal length forms no real image, and no aperture brings it into focus
    (the closed form would give a negative N there)."""
    s = np.asarray(s_m, float)
    f = np.asarray(focal_length_m, float)
    d = np.asarray(dof_m, float)
    a = (s - f) * (s + np.sqrt(s**2 + d**2)) / d
    with np.errstate(divide="ignore"):
        return np.where(s > f, f**2 / (np.asarray(coc_m, float) * a), np.inf)


def min_f_number(s_m, focal_length_m, coc_m, dof_m, port, water_index, dome=None, iterations=60, flat=(0.0, 0.0, 1.0)):
    """Smallest N whose underwater depth of field (far − near) reaches dof_m (a flat port maps distances
    affinely, v = offset + s / n_w, so depths shrink by n_w); inf where none does."""
    if port != "dome":
        n = np.asarray(water_index, float)
        apparent = port_model.flat_apparent_distance(s_m, n, *flat)
        return min_f_number_in_air(apparent, focal_length_m, coc_m, np.asarray(dof_m) / n)
    shape = np.broadcast_shapes(*(np.shape(x) for x in (s_m, focal_length_m, coc_m, dof_m, water_index, *dome)))
    lo = np.full(shape, np.log(0.05))
    hi = np.full(shape, np.log(1.0e4))
    reached = np.zeros(shape, bool)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        near, far = dof_underwater(s_m, focal_length_m, np.exp(mid), coc_m, port, water_index, dome)
        enough = (far - near) >= dof_m
        reached |= enough
        hi = np.where(enough, mid, hi)
        lo = np.where(enough, lo, mid)
    return np.where(reached, np.exp(hi), np.inf)  # inf: not even N = 1e4 reaches it (e.g. a target within f)
