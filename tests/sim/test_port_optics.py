"""Exact port optics against closed forms: Snell's law, slabs, concentric domes, apparent depth, virtual images,
focusing aids and the lens model (checked against OpenCV's own projection)."""

import cv2
import numpy as np
import pytest

from uwlab.model import focus, port
from uwlab.model.lens import BrownLens
from uwlab.model.port_field import exact_fov_rad, focal_ratio, port_distortion, virtual_image_z, water_field_angle
from uwlab.model.raytrace import DomePort, FlatPort, normalize, refract

RNG = np.random.default_rng(15)
DIRECTIONS = normalize(np.c_[RNG.uniform(-0.8, 0.8, (500, 2)), np.ones(500)])


def _sin_from_axis(d, axis=(0.0, 0.0, 1.0)):
    return np.linalg.norm(np.cross(d, axis), axis=-1)


def test_refraction_obeys_snell_in_the_plane_of_incidence_and_flags_total_internal_reflection():
    normal = np.array([0.0, 0.0, 1.0])
    t, tir = refract(DIRECTIONS, normal, 1.0, 1.5)
    assert not tir.any()
    np.testing.assert_allclose(1.5 * _sin_from_axis(t), _sin_from_axis(DIRECTIONS), rtol=1e-12)
    coplanar = np.einsum("ij,ij->i", np.cross(DIRECTIONS, normal), t)
    np.testing.assert_allclose(coplanar, 0.0, atol=1e-14)
    critical = np.arcsin(1 / 1.5)
    angles = np.array([critical - 1e-3, critical + 1e-3])
    d = np.c_[np.sin(angles), 0 * angles, np.cos(angles)]
    t, tir = refract(d, normal, 1.5, 1.0)
    assert tir.tolist() == [False, True] and np.isnan(t[1]).all() and np.isfinite(t[0]).all()


@pytest.mark.parametrize("thickness_mm", [0.0, 3.0, 12.0, 60.0])
@pytest.mark.parametrize("gap_mm", [0.0, 7.5])
def test_flat_port_gives_snell_between_air_and_water_for_every_thickness(thickness_mm, gap_mm):
    flat = FlatPort(thickness_mm * 1e-3, gap_mm * 1e-3, 1.49, 1.333)
    rays = flat.trace(DIRECTIONS)
    assert rays.valid.all()
    np.testing.assert_allclose(_sin_from_axis(rays.directions), _sin_from_axis(DIRECTIONS) / 1.333, rtol=1e-12)
    # the exit point: r = g tan θa + t tan θg (a plane-parallel slab)
    sin_a = _sin_from_axis(DIRECTIONS)
    tan_a = sin_a / DIRECTIONS[:, 2]
    sin_g = sin_a / 1.49
    r = gap_mm * 1e-3 * tan_a + thickness_mm * 1e-3 * sin_g / np.sqrt(1 - sin_g**2)
    np.testing.assert_allclose(np.hypot(*rays.points[:, :2].T), r, rtol=1e-10, atol=1e-15)
    assert focal_ratio(flat) == pytest.approx(1.333, rel=1e-8)


def test_tilted_flat_port_passes_a_ray_along_its_normal_undeviated():
    flat = FlatPort(0.01, 0.005, 1.49, 1.333, (np.radians(4.0), np.radians(-2.5)))
    rays = flat.trace(flat.normal[None, :])
    np.testing.assert_allclose(rays.directions[0], flat.normal, atol=1e-15)
    tilted = flat.trace(np.array([[0.0, 0.0, 1.0]])).directions[0]
    assert np.degrees(np.arccos(tilted[2])) > 0.5


def test_centred_dome_refracts_nothing_and_keeps_the_in_air_field_of_view():
    dome = DomePort(0.05, 0.006, 1.49, 1.333)
    rays = dome.trace(DIRECTIONS)
    np.testing.assert_allclose(rays.directions, DIRECTIONS, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(rays.points, axis=1), 0.05, rtol=1e-14)
    size, f = (8.45e-3, 7.07e-3), 8e-3
    fov = exact_fov_rad(dome, size, f)
    assert fov["x"] == pytest.approx(2 * np.arctan(size[0] / 2 / f), rel=1e-12)
    assert fov["y"] == pytest.approx(2 * np.arctan(size[1] / 2 / f), rel=1e-12)
    pct, shift = port_distortion(dome, np.array([[4e-3, 3e-3], [-4e-3, 0.0]]), f)
    np.testing.assert_allclose(pct, 0.0, atol=1e-9)


def test_flat_port_field_of_view_and_distortion_match_snell_closed_forms():
    flat = FlatPort(0.008, 0.004, 1.49, 1.333)
    size, f = (8.45e-3, 7.07e-3), 8e-3
    for axis, s in zip("xy", size, strict=True):
        theta_a = np.arctan(s / 2 / f)
        assert exact_fov_rad(flat, size, f)[axis] == pytest.approx(2 * np.arcsin(np.sin(theta_a) / 1.333), rel=1e-12)
    xy = np.c_[np.linspace(1e-4, 5e-3, 7), np.linspace(0, 3e-3, 7)]
    theta_a = np.arctan(np.hypot(*xy.T) / f)
    theta_w = np.arcsin(np.sin(theta_a) / 1.333)
    np.testing.assert_allclose(water_field_angle(flat, xy, f), theta_w, rtol=1e-12)
    pct, _ = port_distortion(flat, xy, f)
    np.testing.assert_allclose(pct, 100 * (np.tan(theta_a) / (1.333 * np.tan(theta_w)) - 1), rtol=1e-6, atol=1e-9)
    assert (pct > 0).all()  # pincushion


@pytest.mark.parametrize("decenter", [(0.002, -0.001, 0.003), (0.0, 0.0, -0.004)])
def test_projection_inverts_tracing(decenter):
    for p in (DomePort(0.05, 0.005, 1.49, 1.333, decenter), FlatPort(0.01, 0.003, 1.52, 1.34, (0.03, -0.02))):
        rays = p.trace(DIRECTIONS)
        scene = rays.points + RNG.uniform(0.2, 3.0, (len(DIRECTIONS), 1)) * rays.directions
        np.testing.assert_allclose(p.project(scene), DIRECTIONS, atol=1e-12)
        origins = np.array([1e-4, -2e-4, 0.0])
        rays = p.trace(DIRECTIONS, origins)
        scene = rays.points + 0.7 * rays.directions
        np.testing.assert_allclose(p.project(scene, origins=origins), DIRECTIONS, atol=1e-12)


def test_virtual_image_on_axis_matches_the_paraxial_formulas():
    dome = DomePort(0.05, 0.005, 1.49, 1.333)
    for s in (0.3, 1.0, 4.0):
        tangential, sagittal = virtual_image_z(dome, np.zeros(2), 8e-3, s)
        expected = port.dome_virtual_distance(s, 0.05, 0.005, 1.333, 1.49)
        assert tangential == pytest.approx(expected, rel=1e-7) and sagittal == pytest.approx(expected, rel=1e-7)
    flat = FlatPort(0.01, 0.005, 1.49, 1.333)
    tangential, sagittal = virtual_image_z(flat, np.zeros(2), 8e-3, 1.5)
    expected = 0.005 + 0.01 / 1.49 + (1.5 - 0.015) / 1.333
    assert tangential == pytest.approx(expected, rel=1e-7) and sagittal == pytest.approx(expected, rel=1e-7)
    assert port.flat_apparent_distance(1.5, 1.333, 0.005, 0.01, 1.49) == pytest.approx(expected, rel=1e-12)


def test_centred_dome_images_a_plane_on_the_concentric_sphere_of_its_distance():
    """Every chief ray of a centred dome is an axis of symmetry: the scene point at D / cos θ from the centre is
    imaged at v(D / cos θ) along the same ray, with no astigmatism."""
    dome = DomePort(0.05, 0.005, 1.49, 1.333)
    f, plane = 8e-3, 1.2
    xy = np.c_[np.linspace(0, 5e-3, 6), np.linspace(0, 2e-3, 6)]
    cos_t = 1 / np.sqrt(1 + (np.hypot(*xy.T) / f) ** 2)
    tangential, sagittal = virtual_image_z(dome, xy, f, plane)
    expected = port.dome_virtual_distance(plane / cos_t, 0.05, 0.005, 1.333, 1.49) * cos_t
    np.testing.assert_allclose(tangential, expected, rtol=1e-6)
    np.testing.assert_allclose(sagittal, expected, rtol=1e-6)
    assert expected[-1] < expected[0]  # field curvature: the edge's image is closer


def test_flat_port_is_astigmatic_off_axis():
    flat = FlatPort(0.01, 0.005, 1.49, 1.333)
    tangential, sagittal = virtual_image_z(flat, np.array([5e-3, 0.0]), 8e-3, 1.5)
    assert tangential < sagittal - 1e-3


def test_decentring_breaks_the_dome_symmetry_in_proportion():
    def edge_distortion(scale):
        dome = DomePort(0.05, 0.005, 1.49, 1.333, (scale * 1e-3, 0.0, scale * 2e-3))
        return port_distortion(dome, np.array([[4e-3, 3e-3]]), 8e-3)[1][0]

    small, double = edge_distortion(0.1), edge_distortion(0.2)
    assert abs(small) > 1e-8
    assert double == pytest.approx(2 * small, rel=0.02)


def test_close_up_lens_and_focus_setting():
    v = np.array([0.12, 0.25, 0.5])
    dpt = focus.close_up_lens_dpt(v, 0.2)
    np.testing.assert_allclose(dpt, [1 / 0.12 - 1 / 0.2, 0.0, 0.0])
    setting = focus.focus_setting_m(v, 0.2)
    np.testing.assert_allclose(setting, [0.2, 0.25, 0.5])
    # a lens set to `setting` behind the close-up lens focuses exactly on v: 1 / (P + 1/s) = v
    np.testing.assert_allclose(1 / (dpt + 1 / setting), v, rtol=1e-12)
    assert np.isnan(focus.close_up_lens_dpt(0.12, None))
    assert focus.target_image_distance_m(1.0, "flat", 1.333) == pytest.approx(1 / 1.333, rel=1e-15)
    dome = (0.05, 0.005, 1.49)
    # decentring by δz moves the pupil: the image seen from it is v(s + δz) − δz
    shifted = focus.target_image_distance_m(1.0, "dome", 1.333, dome=dome, decenter_z_m=0.002)
    assert shifted == pytest.approx(port.dome_virtual_distance(1.002, 0.05, 0.005, 1.333, 1.49) - 0.002, rel=1e-12)
    traced = virtual_image_z(DomePort(0.05, 0.005, 1.49, 1.333, (0.0, 0.0, 0.002)), np.zeros(2), 8e-3, 1.0)[0]
    assert traced == pytest.approx(shifted, rel=1e-6)


def test_flat_apparent_distance_round_trip_and_thin_limit():
    s = np.array([0.3, 1.0, 7.0])
    np.testing.assert_array_equal(port.flat_apparent_distance(s, 1.34), s / 1.34)
    v = port.flat_apparent_distance(s, 1.34, 0.004, 0.012, 1.52)
    np.testing.assert_allclose(port.flat_object_distance(v, 1.34, 0.004, 0.012, 1.52), s, rtol=1e-14)


def test_lens_model_agrees_with_opencv_and_inverts():
    lens = BrownLens(580.0, 578.0, 305.2, 254.7, (-0.12, 0.03, 0.001, -0.0007, 0.004))
    d = DIRECTIONS[:100]
    ours = lens.pixels(d)
    theirs, _ = cv2.projectPoints(d, np.zeros(3), np.zeros(3), lens.camera_matrix, np.asarray(lens.distortion))
    np.testing.assert_allclose(ours, theirs.reshape(-1, 2), atol=1e-6)
    np.testing.assert_allclose(lens.rays(ours), d, atol=1e-12)
