"""The predicted MTF's stages against their closed forms and against the depth of field computed independently
(`uwlab.model.optics`: the hyperfocal construction), and MTF50 of a design against focus and f-number."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from tests.support.paths import CONFIGS

from uwlab.model import mtf, optics, port
from uwlab.model.build import load_design
from uwlab.model.chain import circle_of_confusion_m


def test_blur_at_the_depth_of_field_limits_is_the_circle_of_confusion():
    """Two constructions of the same thin lens: at the near and far limits of `dof_underwater` (hyperfocal
    distance) the blur disk of `defocus_blur_diameter_m` (image-space similar triangles) is exactly the CoC."""
    f, n_stop, coc, s, n_w = 0.012, 4.0, 5e-6, 1.0, 1.34
    near, far = optics.dof_underwater(s, f, n_stop, coc, "flat", n_w)
    v_focus = port.flat_apparent_distance(s, n_w)
    for limit in (near, far):
        blur = mtf.defocus_blur_diameter_m(port.flat_apparent_distance(limit, n_w), v_focus, f, n_stop)
        assert blur == pytest.approx(coc, rel=1e-9)


def test_each_stage_meets_its_closed_form():
    c = 20e-6  # a 20 µm blur disk: first zero of 2 J1(x)/x at x = 3.8317
    assert mtf.defocus_mtf(3.8317 / (np.pi * c), c) == pytest.approx(0.0, abs=1e-4)
    assert mtf.defocus_mtf(0.0, c) == 1.0
    cutoff = 1 / (550e-9 * 4.0)
    assert mtf.diffraction_mtf(cutoff / 2, 4.0) == pytest.approx((2 / np.pi) * (np.pi / 3 - 0.5 * np.sqrt(0.75)))
    assert mtf.diffraction_mtf(cutoff * 1.01, 4.0) == 0.0
    assert mtf.pixel_mtf(1.0) == pytest.approx(0.0, abs=1e-12)
    assert mtf.motion_mtf(0.25, 4.0) == pytest.approx(0.0, abs=1e-12)  # a 4 px smear cancels 0.25 cy/px


def test_mtf50_of_a_pixel_alone_is_the_sinc_half_point():
    """No defocus, no motion, a vanishing diffraction term (f/0.0001): MTF50 is where sinc falls to 0.5."""
    truth = brentq(lambda f: np.sinc(f) - 0.5, 0.1, 0.9)
    got = mtf.mtf50_cy_per_px(pixel_pitch_m=3.45e-6, blur_diameter_m=0.0, f_number=1e-4)
    assert got == pytest.approx(truth, abs=1e-4)


def test_a_design_is_sharpest_focused_on_the_target_and_stopping_down_helps_a_defocused_lens():
    design = load_design(CONFIGS / "design" / "example.toml")
    focused = float(mtf.design_mtf50(design.with_values(**{"operation.exposure_s": 1e-5})))
    settings = np.linspace(0.6, 0.9, 31)
    d = design.with_values(**{"operation.exposure_s": 1e-5})
    curve = [float(mtf.design_mtf50(d, focus_setting_m=v)) for v in settings]
    best = settings[int(np.nanargmax(curve))]
    image = float(d.values["operation"]["altitude_m"])
    focused_image = port.flat_apparent_distance(
        image,
        d["housing.water_index"],
        d["housing.flat_air_gap_mm"] * 1e-3,
        d["housing.flat_thickness_mm"] * 1e-3,
        d["housing.port_index"],
    )
    assert abs(best - float(focused_image)) <= 0.01
    assert focused >= max(curve) > 0.99 * focused
    off = 0.95 * float(focused_image)
    wide = float(mtf.design_mtf50(d.with_values(**{"lens.f_number": 2.0}), focus_setting_m=off))
    stopped = float(mtf.design_mtf50(d.with_values(**{"lens.f_number": 8.0}), focus_setting_m=off))
    assert stopped > wide
    assert circle_of_confusion_m(d) > 0
