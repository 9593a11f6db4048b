"""`uwlab design` end to end: JSON keys, grids, plots, and one-line errors with exit code 2."""

import json

import pandas as pd
import pytest

from uwlab.cli.main import main
from tests.support.cli import one_line_error
from tests.support.paths import EXAMPLE

KEYS = {
    "effective_focal_length_mm",
    "fov_deg",
    "fov_m",
    "max_exposure_s",
    "exposure_s",
    "min_framerate_hz",
    "dof_m",
    "min_f_number_for_dof",
    "dome_virtual_image_m",
    "focus_image_m",
    "focus_setting_m",
    "close_up_lens_dpt",
    "target_irradiance_w_m2",
    "sensor_irradiance_w_m2",
    "mean_electrons",
    "mean_dn",
    "mean_fraction",
    "saturated",
    "snr",
    "snr_db",
    "image_average",
    "light_budget_stops",
}


def run_cli(capsys, *args):
    code = main(["design", str(EXAMPLE), *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_json_has_every_documented_key(capsys):
    code, out, _ = run_cli(capsys, "--json")
    result = json.loads(out)
    assert code == 0 and set(result) == KEYS
    assert set(result["fov_deg"]) == {"x", "y"} and set(result["dof_m"]) == {"near", "far"}
    assert set(result["image_average"]) == {"mean_electrons", "mean_dn", "snr"}
    assert result["dome_virtual_image_m"] is None
    assert result["snr_db"] == pytest.approx(20 * __import__("math").log10(result["snr"]))


def test_set_overrides_and_max_blur(capsys):
    code, out, _ = run_cli(capsys, "--json", "--set", "operation.exposure_s=max-blur", "--set", "lens.f_number=4")
    result = json.loads(out)
    assert code == 0 and result["exposure_s"] == pytest.approx(result["max_exposure_s"])


def test_grid_to_parquet(capsys, tmp_path):
    out_file = tmp_path / "grid.parquet"
    code, out, _ = run_cli(
        capsys,
        "--grid",
        "operation.altitude_m=0.5:2.0:0.5",
        "--grid",
        "lens.f_number=2,4,8",
        "--grid",
        "water.type=jerlov-I,jerlov-9C",
        "--out",
        str(out_file),
        "--json",
    )
    assert code == 0 and json.loads(out)["points"] == 24
    frame = pd.read_parquet(out_file)
    assert len(frame) == 24 and {"operation.altitude_m", "lens.f_number", "water.type", "snr"} <= set(frame.columns)
    clear = frame[(frame["water.type"] == "jerlov-I")]["target_irradiance_w_m2"].to_numpy()
    murky = frame[(frame["water.type"] == "jerlov-9C")]["target_irradiance_w_m2"].to_numpy()
    assert (murky < clear).all()
    code, _, err = run_cli(capsys, "--grid", "lens.f_number=2,4", "--out", str(out_file))
    assert code == 2 and "exists" in err


def test_plots_are_written(capsys, tmp_path):
    code, out, _ = run_cli(capsys, "--plot", str(tmp_path))
    assert code == 0
    names = {p.name for p in tmp_path.glob("*.png")}
    assert names == {"dof.png", "spectra.png", "operation.png", "water.png", "qe.png"}
    assert all(p.stat().st_size > 10_000 for p in tmp_path.glob("*.png"))


@pytest.mark.parametrize(
    "override, key",
    [
        ("light.colour=5", "light.colour"),
        ("lens.f_number=0", "lens.f_number"),
        ("lens.f_number=-2", "lens.f_number"),
        ("operation.overlap=1.0", "operation.overlap"),
        ("operation.altitude_m=-3", "operation.altitude_m"),
        ("light.distance_m='far'", "light.distance_m"),
        ("sensor.profile='imx999'", "sensor.profile"),
        ("water.type='jerlov-X'", "water.type"),
        ("water.type='missing.csv'", "water.type"),
        ("target.reflectance=1.5", "target.reflectance"),
        ("sensor.gain_db=80", "sensor.gain_db"),
        ("housing.port='dome'", "housing.dome_radius_mm"),
        ("operation.motion_axis='z'", "operation.motion_axis"),
        ("camera.zoom=2", "camera"),
    ],
)
def test_bad_input_is_one_line_naming_the_key(capsys, override, key):
    assert key in one_line_error(capsys, ["design", str(EXAMPLE), "--set", override])


def test_missing_config_file_and_bad_grid(capsys, tmp_path):
    code = main(["design", str(tmp_path / "nope.toml")])
    err = capsys.readouterr().err
    assert code == 2 and "nope.toml" in err and "not found" in err
    code, _, err = run_cli(capsys, "--grid", "lens.f_number=4:2:1")
    assert code == 2 and "lens.f_number" in err
