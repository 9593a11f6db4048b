"""What exact refraction says about a design's port across the field: the exact field of view, the distortion the
port adds, the virtual image of the scene plane at each field angle, and the error of the paraxial rule.

Conventions (those of `uwlab.model.raytrace`): camera axes at the entrance pupil, z along the optical axis; the
lens is an ideal pinhole of focal length f, so an image point (x, y) on the sensor [m], measured from the
principal point at the sensor's centre, looks along (x/f, y/f, 1) in air. Field angles in the water are taken
from the water-side ray of the image centre (the port's axis as the camera sees it).

- Port focal ratio f_uw/f: the ratio of a small angle in air to the angle it becomes in the water, about the
  image centre (objects at infinity): n_w for a flat port of any thickness (paraxial Snell), 1 for a centred dome.
- Distortion the port adds (objects at infinity): an image point at radius r sees the water angle θ_w; a pinhole
  of focal length f_uw would put it at r_p = f_uw tan θ_w. D = (r − r_p)/r_p [%], and r − r_p [px]. A flat port
  gives D = tan θ_a / (n_w tan θ_w) − 1 > 0 with sin θ_w = sin θ_a / n_w (pincushion; Treibitz et al. 2012).
- Paraxial rule (what `uwlab design` assumes: tan θ_w = tan θ_a / n_w behind a flat port, θ_w = θ_a behind a
  dome): its error is θ_rule − θ_w [deg] and, in the image, r − f_rule tan θ_w [px].
- Virtual image of the scene plane z = s (field curvature and astigmatism): for the scene point on the chief ray
  of an image point, two rays from pupil points offset by ±h (h = 0.1 mm) in the meridional (tangential) or the
  perpendicular (sagittal) direction are traced back into the air; the point of closest approach of each with
  the chief ray is that focus (symmetric offsets cancel the first-order error; pencils of h and 2h are
  extrapolated to zero width). Its axial distance z from the pupil is where the lens must focus; the medial
  image is the mean of the tangential and sagittal ones.
  On axis behind a centred dome this is the paraxial image of `uwlab.model.port.dome_virtual_distance`; behind a
  flat port, g + t/n_p + (s − g − t)/n_w.
"""

from __future__ import annotations

import numpy as np

from uwlab.model import focus, optics
from uwlab.model.design import circle_of_confusion_m, effective_focal_length_m, port_geometry
from uwlab.model.raytrace import FlatPort, Port, normalize, port_from_housing

PUPIL_OFFSET_M = 1e-4
SLOPE_STEP = 1e-5


def port_of(d) -> Port:
    """The exact port of a scalar design (`uwlab.model.design.Design`)."""
    return port_from_housing(d.values["housing"])


def pinhole_directions(xy_m, focal_length_m):
    """Unit directions in air of image points xy_m (..., 2) [m from the principal point] of a pinhole lens."""
    xy = np.asarray(xy_m, float)
    return normalize(np.concatenate([xy / focal_length_m, np.ones(xy.shape[:-1] + (1,))], axis=-1))


def _angle(a, b):
    """Angle between unit vectors along the last axis [rad] (atan2 form: accurate for small angles)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def water_directions(port: Port, xy_m, focal_length_m):
    """Unit directions in the water of the rays of image points xy_m (NaN where a ray does not get out)."""
    rays = port.trace(pinhole_directions(xy_m, focal_length_m))
    return np.where(rays.valid[..., None], rays.directions, np.nan)


def focal_ratio(port: Port) -> float:
    """f_uw / f: a small angle in air over the angle it becomes in water, about the image centre (x and y mean)."""
    ratios = []
    for axis in (0, 1):
        slopes = np.zeros((2, 2))
        slopes[:, axis] = (-SLOPE_STEP, SLOPE_STEP)
        dw = port.trace(normalize(np.c_[slopes, np.ones(2)])).directions
        ratios.append(2 * np.arctan(SLOPE_STEP) / _angle(dw[0], dw[1]))
    return float(np.mean(ratios))


def water_field_angle(port: Port, xy_m, focal_length_m):
    """Angle in the water between the ray of each image point and the ray of the image centre [rad]."""
    axis = water_directions(port, np.zeros(2), focal_length_m)
    return _angle(water_directions(port, xy_m, focal_length_m), axis)


def port_distortion(port: Port, xy_m, focal_length_m):
    """(D [%], r − r_p [m on the sensor]) of image points xy_m: the radial distortion the port adds."""
    r = np.linalg.norm(np.asarray(xy_m, float), axis=-1)
    r_p = focal_ratio(port) * focal_length_m * np.tan(water_field_angle(port, xy_m, focal_length_m))
    with np.errstate(invalid="ignore", divide="ignore"):
        return 100.0 * (r / r_p - 1.0), r - r_p


def paraxial_rule_ratio(port: Port) -> float:
    """f_uw/f of the paraxial rule `uwlab design` uses: n_w behind a flat port, 1 behind a dome."""
    return port.water_index if isinstance(port, FlatPort) else 1.0


def paraxial_error(port: Port, xy_m, focal_length_m):
    """(θ_rule − θ_w [rad], r − f_rule tan θ_w [m on the sensor]) of the paraxial rule at image points xy_m."""
    r = np.linalg.norm(np.asarray(xy_m, float), axis=-1)
    ratio = paraxial_rule_ratio(port)
    theta_w = water_field_angle(port, xy_m, focal_length_m)
    theta_rule = np.arctan(r / focal_length_m / ratio)
    return theta_rule - theta_w, r - ratio * focal_length_m * np.tan(theta_w)


def exact_fov_rad(port: Port, sensor_size_m, focal_length_m) -> dict[str, float]:
    """Full angles in the water between the rays of opposite sensor edges, along x and y."""
    half_x, half_y = (s / 2 for s in sensor_size_m)
    edges = {"x": np.array([[-half_x, 0.0], [half_x, 0.0]]), "y": np.array([[0.0, -half_y], [0.0, half_y]])}
    out = {}
    for axis, xy in edges.items():
        dw = water_directions(port, xy, focal_length_m)
        out[axis] = float(_angle(dw[0], dw[1]))
    return out


def virtual_image_z(port: Port, xy_m, focal_length_m, plane_distance_m, h=PUPIL_OFFSET_M):
    """(tangential, sagittal) axial distances from the pupil [m] of the virtual image of the scene plane
    z = plane_distance_m at image points xy_m (..., 2): pencils of half-width h and 2h, extrapolated to zero
    width (Richardson: the focus shifts as h², spherical aberration)."""
    xy = np.asarray(xy_m, float)
    chief = pinhole_directions(xy, focal_length_m)
    scene = port.trace(chief).at_plane((0.0, 0.0, 1.0), plane_distance_m)
    r = np.linalg.norm(xy, axis=-1, keepdims=True)
    radial = np.where(r > 0, xy / np.where(r > 0, r, 1.0), np.array([1.0, 0.0]))
    tangential = np.concatenate([radial, np.zeros(r.shape)], axis=-1)
    sagittal = np.concatenate([-radial[..., 1:], radial[..., :1], np.zeros(r.shape)], axis=-1)
    out = []
    for offset in (tangential, sagittal):
        z1, z2 = (_pencil_focus_z(port, chief, scene, width * offset) for width in (h, 2 * h))
        out.append((4 * z1 - z2) / 3)
    return out[0], out[1]


def _pencil_focus_z(port: Port, chief, scene, offset):
    """Axial distance of the mean closest approach to the chief ray of the rays from pupil points ±offset
    that reach the scene points."""
    z = []
    for origin in (offset, -offset):
        d1 = port.project(scene, origins=origin)
        b = np.sum(chief * d1, axis=-1)
        s0 = (b * np.sum(d1 * -origin, axis=-1) - np.sum(chief * -origin, axis=-1)) / (1.0 - b**2)
        z.append(s0 * chief[..., 2])
    return 0.5 * (z[0] + z[1])


def _worst(values) -> float:
    """The sample of largest magnitude (signed), NaN-aware."""
    values = np.asarray(values, float)
    return float(values[np.nanargmax(np.abs(values))])


def trace_design(d, samples: int = 41) -> dict:
    """Exact port optics of a scalar design: summary figures (the keys of `uwlab port trace --json`) and the
    radial profiles behind them (key "profile", for plots). Sizes in pixels use the sensor's pixel pitch."""
    port = port_of(d)
    f = float(d["lens.focal_length_mm"]) * 1e-3
    pixel = d.sensor.pixel_size_um * 1e-6
    size = d.sensor.size_m
    half_x, half_y = size[0] / 2, size[1] / 2
    edges = np.array([[half_x, 0.0], [-half_x, 0.0]])
    corners = np.array([[half_x, half_y], [-half_x, half_y], [half_x, -half_y], [-half_x, -half_y]])
    altitude = float(d["operation.altitude_m"])

    dist_pct_e, dist_m_e = port_distortion(port, edges, f)
    dist_pct_c, dist_m_c = port_distortion(port, corners, f)
    err_rad_e, err_m_e = paraxial_error(port, edges, f)
    err_rad_c, err_m_c = paraxial_error(port, corners, f)
    tan_axis, sag_axis = virtual_image_z(port, np.zeros(2), f, altitude)
    tan_edge, sag_edge = virtual_image_z(port, edges, f, altitude)
    tan_corner, sag_corner = virtual_image_z(port, corners, f, altitude)
    image_axis = 0.5 * (tan_axis + sag_axis)
    image_edge = 0.5 * (tan_edge + sag_edge)
    f_eff = float(effective_focal_length_m(d))
    paraxial_fov = {a: float(np.degrees(optics.angular_fov_rad(s, f_eff))) for a, s in zip("xy", size, strict=True)}

    u = np.linspace(0.0, 1.0, samples)
    directions = {
        "x": np.c_[u * half_x, 0 * u],
        "y": np.c_[0 * u, u * half_y],
        "diagonal": np.c_[u * half_x, u * half_y],
    }
    profile = {
        "field_deg_air": {},
        "image_radius_px": {},
        "distortion_percent": {},
        "distortion_px": {},
        "paraxial_error_deg": {},
        "virtual_image_tangential_m": {},
        "virtual_image_sagittal_m": {},
    }
    for name, xy in directions.items():
        r = np.linalg.norm(xy, axis=-1)
        pct, metres = port_distortion(port, xy, f)
        err, _ = paraxial_error(port, xy, f)
        tan_z, sag_z = virtual_image_z(port, xy, f, altitude)
        profile["field_deg_air"][name] = np.degrees(np.arctan(r / f))
        profile["image_radius_px"][name] = r / pixel
        profile["distortion_percent"][name] = np.where(r > 0, pct, 0.0)
        profile["distortion_px"][name] = metres / pixel
        profile["paraxial_error_deg"][name] = np.degrees(err)
        profile["virtual_image_tangential_m"][name] = tan_z
        profile["virtual_image_sagittal_m"][name] = sag_z

    return {
        "port": d["housing.port"],
        "fov_deg": {a: float(np.degrees(v)) for a, v in exact_fov_rad(port, size, f).items()},
        "paraxial_fov_deg": paraxial_fov,
        "focal_ratio": focal_ratio(port),
        "paraxial_focal_ratio": paraxial_rule_ratio(port),
        "distortion_percent": {"edge": _worst(dist_pct_e), "corner": _worst(dist_pct_c)},
        "distortion_px": {"edge": _worst(dist_m_e / pixel), "corner": _worst(dist_m_c / pixel)},
        "paraxial_error_deg": {"edge": _worst(np.degrees(err_rad_e)), "corner": _worst(np.degrees(err_rad_c))},
        "paraxial_error_px": {"edge": _worst(err_m_e / pixel), "corner": _worst(err_m_c / pixel)},
        "virtual_image_m": {
            "on_axis": float(image_axis),
            "edge": float(image_edge[np.argmax(np.abs(image_edge - image_axis))]),
        },
        "focus": focus_aids(d, float(image_axis), np.r_[tan_edge, sag_edge], np.r_[tan_corner, sag_corner]),
        "profile": profile,
    }


def focus_aids(d, image_axis_m: float, image_edge_m, image_corner_m) -> dict:
    """Focusing aids from the traced virtual images: focus setting and close-up lens for the on-axis image, the
    depth of field in water around the working altitude, and whether the images (tangential and sagittal) of
    the edges and of the corners lie within the lens's depth of field (image space, in air) when it is focused
    on axis."""
    min_focus = d["lens.min_focus_distance_m"]
    f = float(d["lens.focal_length_mm"]) * 1e-3
    n = float(d["lens.f_number"])
    coc_m = float(circle_of_confusion_m(d))
    setting = float(focus.focus_setting_m(image_axis_m, min_focus))
    dpt = float(focus.close_up_lens_dpt(image_axis_m, min_focus))
    near_a, far_a = optics.dof_in_air(image_axis_m, f, n, coc_m)
    near_w, far_w = _dof_in_water(d, f, n, coc_m)

    def inside(images):
        images = np.asarray(images, float)
        return bool(np.all((images >= near_a) & (images <= far_a)))

    return {
        "image_distance_m": image_axis_m,
        "setting_m": setting,
        "close_up_lens_dpt": None if min_focus is None else dpt,
        "dof_m": {"near": float(near_w), "far": float(far_w)},
        "image_dof_m": {"near": float(near_a), "far": float(far_a)},
        "edge_in_focus": inside(image_edge_m),
        "corner_in_focus": inside(image_corner_m),
    }


def _dof_in_water(d, f, n, coc_m):
    port, n_w, flat, dome, _ = port_geometry(d)
    return optics.dof_underwater(float(d["operation.altitude_m"]), f, n, coc_m, port, n_w, dome, flat)
