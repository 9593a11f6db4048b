"""Ports, field of view, depth of field and operation limits against closed forms and hand cases."""

import numpy as np
import pytest

from uwlab.model import optics, port


def test_fresnel_glass_in_air():
    assert port.fresnel_reflectance(1.0, 1.5) == pytest.approx(0.04)
    # two surfaces, incoherent multiple reflections: T = (1-R)^2 / (1-R^2) = (1-R)/(1+R)
    r = port.fresnel_reflectance(1.5, 1.0)
    assert port.port_transmittance(1.0, 1.5) == pytest.approx((1 - r) / (1 + r))
    assert port.port_transmittance(1.333, 1.333) == pytest.approx(1 - port.fresnel_reflectance(1.333, 1.0))


def test_thin_dome_images_infinity_at_n_r_over_n_minus_1():
    n_w, radius = 1.333, 0.1
    v_inf = port.dome_virtual_distance(np.inf, radius, 1e-9, n_w, 1.49)
    assert v_inf == pytest.approx(n_w * radius / (n_w - 1), rel=1e-6)


@pytest.mark.parametrize("u", [0.3, 1.0, 3.0, 20.0])
def test_dome_mapping_round_trip(u):
    v = port.dome_virtual_distance(u, 0.1, 0.012, 1.34, 1.52)
    assert 0 < v < port.dome_virtual_distance(np.inf, 0.1, 0.012, 1.34, 1.52)
    assert port.dome_object_distance(v, 0.1, 0.012, 1.34, 1.52) == pytest.approx(u, rel=1e-9)


def test_dome_object_at_the_surface_images_on_the_surface():
    """An object on the outer surface is imaged in place (both refractions at its own position or beyond)."""
    radius, thickness = 0.1, 1e-9
    assert port.dome_virtual_distance(radius, radius, thickness, 1.333, 1.5) == pytest.approx(radius, rel=1e-6)


def test_fov_hand_case():
    size = 2448 * 3.45e-6
    fov = optics.angular_fov_rad(size, 0.030 * 1.333)
    assert np.degrees(fov) == pytest.approx(2 * np.degrees(np.arctan(8.4456 / 2 / 39.99)), rel=1e-9)
    assert optics.spatial_fov_m(fov, 2.0) == pytest.approx(2.0 * size / 0.03999, rel=1e-9)


def test_dof_matches_paper_approximation_for_distant_focus():
    f, n, c = 0.008, 4.0, 5e-6  # hyperfocal 3.2 m
    for s in (0.5, 1.0, 1.5):
        near, far = optics.dof_in_air(s, f, n, c)
        approx = 2 * n * c * f**2 * s**2 / (f**4 - n**2 * c**2 * s**2)
        # exact = 2as(s-f)/(a^2-(s-f)^2) with a = f^2/(Nc): differs from the approximation at order f/s
        assert far - near == pytest.approx(approx, rel=2 * f / s)
        assert far - near != pytest.approx(approx, rel=1e-3 * f / s)


def test_focus_at_hyperfocal_gives_infinite_far_and_half_near():
    f, n, c = 0.012, 8.0, 5e-6
    h = f**2 / (n * c) + f
    near, far = optics.dof_in_air(h * 1.000001, f, n, c)
    assert np.isinf(far)
    assert near == pytest.approx(h / 2, rel=1e-3)


@pytest.mark.parametrize("port_kind", ["flat", "dome"])
def test_min_f_number_round_trip(port_kind):
    dome = (0.1, 0.01, 1.49) if port_kind == "dome" else None
    s, f, c, dof = 2.0, 0.012, 4.6e-6, np.array([0.3, 1.0, 2.5])
    n_min = optics.min_f_number(s, f, c, dof, port_kind, 1.333, dome)
    near, far = optics.dof_underwater(s, f, n_min, c, port_kind, 1.333, dome)
    assert far - near == pytest.approx(dof, rel=1e-6)
    near, far = optics.dof_underwater(s, f, n_min * 0.99, c, port_kind, 1.333, dome)
    assert np.all(far - near < dof)


@pytest.mark.parametrize("port_kind", ["flat", "dome"])
def test_a_target_within_the_focal_length_has_no_depth_of_field_and_no_f_number(port_kind):
    """An object closer than f forms no real image (1/v = 1/f − 1/s < 0): no aperture focuses it. The closed form
    would give a negative f-number there (−4087 for an altitude of 1e-308 m); it is inf, and the depth of field
    empty, while just beyond f both are finite and positive."""
    dome = (0.1, 0.01, 1.49) if port_kind == "dome" else None
    f, c = 0.012, 4.6e-6
    n_min = optics.min_f_number(np.array([1e-3, 5e-3]), f, c, 0.3, port_kind, 1.333, dome)
    assert np.all(np.isinf(n_min))
    near, far = optics.dof_underwater(np.array([1e-3, 5e-3]), f, 2.8, c, port_kind, 1.333, dome)
    assert np.all(far - near == 0)
    assert optics.min_f_number_in_air(0.005, f, c, 0.3) == np.inf
    beyond = optics.min_f_number_in_air(2 * f, f, c, 1e-3)
    near, far = optics.dof_in_air(2 * f, f, beyond, c)
    assert 0 < beyond < np.inf and far - near == pytest.approx(1e-3, rel=1e-9)


def test_flat_port_dof_is_apparent_distance_mapping():
    near_air, far_air = optics.dof_in_air(1.5 / 1.333, 0.01, 2.8, 5e-6)
    near, far = optics.dof_underwater(1.5, 0.01, 2.8, 5e-6, "flat", 1.333)
    assert (near, far) == pytest.approx((near_air * 1.333, far_air * 1.333))


def test_lens_irradiance_factor():
    assert optics.lens_irradiance_factor(2.0) == pytest.approx(np.pi / 16)
    assert optics.lens_irradiance_factor(1.0, np.cos(np.radians(60))) == pytest.approx(np.pi / 4 / 16)
