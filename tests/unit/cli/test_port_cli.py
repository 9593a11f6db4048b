"""`uwlab port trace`, `uwlab port board` and the focusing aids of `uwlab design`: keys, closed-form values,
figures, and one-line errors with exit code 2."""

import json
import math

import numpy as np
import pytest

from tests.support.cli import one_line_error
from tests.support.paths import EXAMPLE, ROOT
from uwlab.cli.main import main
from uwlab.model import port

DOME = ROOT / "configs" / "design" / "dome-8mm.toml"


def run(capsys, *args):
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def test_trace_json_keys_and_centred_dome_closed_forms(capsys):
    code, out, _ = run(capsys, "port", "trace", str(DOME), "--json")
    result = json.loads(out)
    assert code == 0
    assert {"fov_deg", "paraxial_fov_deg", "distortion_percent", "virtual_image_m", "focus"} <= set(result)
    assert set(result["fov_deg"]) == {"x", "y"} and set(result["distortion_percent"]) == {"edge", "corner"}
    assert set(result["virtual_image_m"]) == {"on_axis", "edge"}
    # a centred dome keeps the in-air field of view (8 mm lens, IMX250: 2·atan(8.4456/16) = 55.65°)
    assert result["fov_deg"]["x"] == pytest.approx(2 * math.degrees(math.atan(2448 * 3.45e-3 / 16)), rel=1e-9)
    assert result["distortion_percent"]["corner"] == pytest.approx(0.0, abs=1e-9)
    v = port.dome_virtual_distance(1.5, 0.05, 0.005, 1.333, 1.49)
    assert result["virtual_image_m"]["on_axis"] == pytest.approx(v, rel=1e-6)
    assert result["virtual_image_m"]["edge"] < v
    # the lens focuses no closer than 0.2 m: a +(1/v − 1/0.2) dpt close-up lens, focus set at 0.2 m
    assert result["focus"]["close_up_lens_dpt"] == pytest.approx(1 / v - 1 / 0.2, rel=1e-5)
    assert result["focus"]["setting_m"] == pytest.approx(0.2)


def test_trace_flat_port_text_and_plots(capsys, tmp_path):
    code, out, _ = run(
        capsys,
        "port",
        "trace",
        str(EXAMPLE),
        "--set",
        "housing.flat_thickness_mm=10",
        "--set",
        "housing.flat_tilt_deg=[2, 0]",
        "--plot",
        str(tmp_path),
    )
    assert code == 0
    assert "field of view, exact (x, y)" in out and "(edge, corner)" in out and "paraxial rule error" in out
    names = {p.name for p in tmp_path.glob("*.png")}
    assert names == {"port_distortion.png", "port_focus.png"}
    assert all(p.stat().st_size > 20_000 for p in tmp_path.glob("*.png"))


def test_astigmatism_of_a_flat_port_puts_the_corner_out_of_focus_first(capsys):
    """8 mm f/2.8 behind a 10 mm window 15 mm from the pupil, target at 1 m: the corner's tangential image
    (34.5° off axis) falls short of the depth of field while the edge's (27.8°) stays inside."""
    code, out, _ = run(
        capsys,
        "port",
        "trace",
        str(EXAMPLE),
        "--json",
        "--set",
        "lens.focal_length_mm=8",
        "--set",
        "lens.f_number=2.8",
        "--set",
        "housing.flat_thickness_mm=10",
        "--set",
        "housing.flat_air_gap_mm=15",
    )
    aid = json.loads(out)["focus"]
    assert code == 0 and aid["edge_in_focus"] is True and aid["corner_in_focus"] is False
    code, out, _ = run(
        capsys,
        "port",
        "trace",
        str(EXAMPLE),
        "--json",
        "--set",
        "lens.focal_length_mm=8",
        "--set",
        "lens.f_number=11",
        "--set",
        "housing.flat_thickness_mm=10",
        "--set",
        "housing.flat_air_gap_mm=15",
    )
    assert json.loads(out)["focus"]["corner_in_focus"] is True


def test_flat_port_trace_json_matches_snell(capsys):
    code, out, _ = run(capsys, "port", "trace", str(EXAMPLE), "--json", "--set", "housing.flat_thickness_mm=25")
    result = json.loads(out)
    half = math.atan(2448 * 3.45e-3 / 60)
    assert result["fov_deg"]["x"] == pytest.approx(2 * math.degrees(math.asin(math.sin(half) / 1.333)), rel=1e-9)
    assert result["fov_deg"]["x"] < result["paraxial_fov_deg"]["x"]
    assert result["distortion_percent"]["corner"] > result["distortion_percent"]["edge"] > 0


def test_design_reports_focusing_aids(capsys):
    code, out, _ = run(capsys, "design", str(DOME), "--json")
    result = json.loads(out)
    v = port.dome_virtual_distance(1.5, 0.05, 0.005, 1.333, 1.49)
    assert result["focus_image_m"] == pytest.approx(v, rel=1e-12)
    assert result["focus_setting_m"] == pytest.approx(0.2)
    assert result["close_up_lens_dpt"] == pytest.approx(1 / v - 5.0, rel=1e-12)
    code, out, _ = run(
        capsys, "design", str(EXAMPLE), "--set", "housing.flat_air_gap_mm=20", "--set", "housing.flat_thickness_mm=12"
    )
    assert code == 0
    expected = 0.02 + 0.012 / 1.49 + (1.0 - 0.032) / 1.333
    line = next(line for line in out.splitlines() if line.startswith("target's image"))
    assert float(line.split()[-2]) == pytest.approx(expected, abs=1e-4)
    assert "close-up lens needed             n/a dpt" in out


def test_design_defaults_keep_the_thin_flat_port_rule(capsys):
    code, out, _ = run(capsys, "design", str(EXAMPLE), "--json")
    result = json.loads(out)
    assert result["focus_image_m"] == 1.0 / 1.333 and result["close_up_lens_dpt"] is None


def test_board_png_prints_at_true_size(capsys, tmp_path):
    from PIL import Image

    out = tmp_path / "board.png"
    code, text, _ = run(capsys, "port", "board", "--out", str(out), "--dpi", "200")
    assert code == 0 and "320 mm × 240 mm" in text
    with Image.open(out) as image:
        width_px = image.size[0]
        dpi = image.info["dpi"][0]
    assert width_px / dpi * 25.4 == pytest.approx(320.0, rel=1e-3)
    code, _, err = run(capsys, "port", "board", "--out", str(out))
    assert code == 2 and "exists" in err


@pytest.mark.parametrize(
    "args, key",
    [
        (["port", "trace", str(DOME), "--set", "housing.dome_decenter_mm=30,0,0"], "housing.dome_decenter_mm"),
        (["port", "trace", str(DOME), "--set", "housing.dome_decenter_mm=1,2"], "housing.dome_decenter_mm"),
        (["port", "trace", str(EXAMPLE), "--set", "housing.flat_tilt_deg=[60, 0]"], "housing.flat_tilt_deg"),
        (["port", "trace", str(EXAMPLE), "--set", "housing.flat_thickness_mm=-1"], "housing.flat_thickness_mm"),
        (["port", "trace", str(EXAMPLE), "--set", "lens.min_focus_distance_m=0"], "lens.min_focus_distance_m"),
        (["port", "trace", str(EXAMPLE), "--set", "lens.f_number"], "--set"),
        (["port", "trace", str(EXAMPLE), "--plot", "/dev/null/plots"], "--plot"),
        (["design", str(EXAMPLE), "--set", "housing.flat_air_gap_mm='near'"], "housing.flat_air_gap_mm"),
    ],
)
def test_bad_input_is_one_line_naming_the_key(capsys, args, key):
    assert key in one_line_error(capsys, args)


def test_trace_refuses_a_grid_value():
    from uwlab.errors import ConfigError
    from uwlab.model.build import load_design
    from uwlab.model.port_field import trace_design

    design = load_design(EXAMPLE, {"housing.water_index": np.array([1.33, 1.34])})
    with pytest.raises(ConfigError, match="housing.water_index"):
        trace_design(design)
