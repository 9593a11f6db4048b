"""The shared design readout (names, rounding, warnings), the figures' data against the design's own numbers, and
the light and lens profile schemas."""

import numpy as np
import pytest

from uwlab.errors import ConfigError
from uwlab.experiments.design.curves import dof_curves, operation_curves, water_attenuation
from uwlab.experiments.design.readout import format_value, output_leaves, rows, table_text
from uwlab.jsonable import to_jsonable
from uwlab.model.components import load_lens_profile, load_light_profile, shipped
from uwlab.model.design import evaluate, load_design
from uwlab.model.water import WATER_TYPES, water_iop

from tests.support.paths import EXAMPLE


def test_rounding_and_unnamed_outputs():
    assert format_value(None, "{:.1f}") == "n/a" and format_value(True, "{}") == "true"
    assert format_value({"near": 0.98765, "far": None}, "{:.3f}") == "0.988, n/a"
    shown = {r.key: r for r in rows({"snr_db": 36.4999, "focus_aid_m": 0.123456})}
    assert (shown["snr_db"].label, shown["snr_db"].text, shown["snr_db"].unit) == ("SNR", "36.5", "dB")
    assert (shown["focus_aid_m"].label, shown["focus_aid_m"].text) == ("focus_aid_m", "0.1235")  # a new output shows
    assert "focus_aid_m" in table_text({"snr_db": 36.4999, "focus_aid_m": 0.123456})


def test_output_leaves_are_the_solver_names():
    result = to_jsonable(evaluate(load_design(EXAMPLE)))
    names = [leaf["name"] for leaf in output_leaves(result)]
    assert {"snr_db", "dof_m.near", "fov_deg.x", "image_average.snr", "light_budget_stops.aperture"} <= set(names)
    assert "dome_virtual_image_m" not in names  # a flat port computes none


def test_figure_curves_pass_through_the_design():
    design = load_design(EXAMPLE, {"lens.f_number": 4.0, "operation.altitude_m": 2.0})
    result = evaluate(design)
    curves = dof_curves(design)
    row = int(np.argmin(abs(curves["focus_m"] - 2.0)))
    near = np.interp(np.log(4.0), np.log(curves["f_number"]), curves["near_m"][row])
    assert near == pytest.approx(float(result["dof_m"]["near"]), rel=2e-3)
    at = int(np.argmin(abs(curves["distance_m"] - 2.0)))
    assert curves["distance_m"][at] == pytest.approx(2.0) and curves["near_at_distance_m"][at] == pytest.approx(
        float(result["dof_m"]["near"])
    )
    op = operation_curves(design)
    speed = float(design["operation.speed_m_s"])
    framerate = np.interp(speed, op["speed_m_s"], op["min_framerate_hz"][list(op["altitude_m"]).index(2.0)])
    assert framerate == pytest.approx(float(result["min_framerate_hz"]), rel=1e-9)  # linear in speed
    assert set(water_attenuation(design.grid)) == set(WATER_TYPES)
    assert water_attenuation(design.grid)["jerlov-I"] == pytest.approx(water_iop("jerlov-I", design.grid).c_per_m)


def test_shipped_light_and_lens_profiles_validate_and_fill_a_design():
    for path in shipped("lights"):
        values = load_light_profile(path).design_values(path.parent)
        design = load_design(EXAMPLE, {k: v for k, v in values.items() if v is not None})
        assert design["light.luminous_flux_lm"] == values["light.luminous_flux_lm"]
        assert design["light.spectrum"] == values["light.spectrum"]
    for path in shipped("lenses"):
        values = load_lens_profile(path).design_values(path.parent)
        assert load_design(EXAMPLE, values)["lens.focal_length_mm"] == values["lens.focal_length_mm"]


@pytest.mark.parametrize(
    "text, key",
    [
        ('name = "x"\nluminous_flux_lm = 1000\nbeam_half_angle_deg = 30\n', "spectrum"),
        ('name = "x"\nluminous_flux_lm = -5\nbeam_half_angle_deg = 30\nspectrum = "generic-led"\n', "luminous_flux_lm"),
        (
            'name = "x"\nluminous_flux_lm = 1000\nbeam_half_angle_deg = 95\nspectrum = "generic-led"\n',
            "beam_half_angle_deg",
        ),
    ],
)
def test_bad_light_profiles_are_one_line(tmp_path, text, key):
    path = tmp_path / "light.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as caught:
        load_light_profile(path)
    assert caught.value.key == f"light profile light.toml: {key}" and "\n" not in str(caught.value)
