"""The design API against the CLI and against itself: the same numbers as `uwlab design --json`, a grid whose rows
are the single designs at those values, a solution that sits exactly on its active requirement."""

import json

import numpy as np
import pytest

import uwlab
from uwlab.cli.main import main
from uwlab.errors import ConfigError
from tests.support.paths import EXAMPLE


def test_evaluate_equals_the_cli_json(capsys):
    assert main(["design", str(EXAMPLE), "--set", "lens.f_number=4", "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    result = uwlab.evaluate(uwlab.load_design(EXAMPLE, lens__f_number=4))
    assert result.outputs == cli


def test_dotted_and_double_underscore_overrides_agree():
    a = uwlab.load_design(EXAMPLE, **{"operation.altitude_m": 2.5})
    b = uwlab.load_design(EXAMPLE, operation__altitude_m=2.5)
    assert a["operation.altitude_m"] == b["operation.altitude_m"] == 2.5


def test_evaluation_table_units_warnings_and_budget():
    result = uwlab.evaluate(uwlab.load_design(EXAMPLE, operation__exposure_s="max-blur"))
    table = result.to_pandas()
    assert table.loc["snr_db", "unit"] == "dB" and table.loc["snr_db", "value"] == result["snr_db"]
    assert table.loc["dof_m.near", "value"] == result.outputs["dof_m"]["near"]
    assert "depth of field" in table.loc["dof_m.near", "warning"]
    assert result.limiting_stage == max(result.light_budget, key=lambda k: result.light_budget[k] or -1)
    assert str(result).splitlines()[0].startswith("effective focal length")


def test_evaluate_refuses_an_array_design():
    design = uwlab.load_design(EXAMPLE).with_values(**{"lens.f_number": np.array([2.0, 4.0])})
    with pytest.raises(ConfigError, match="uwlab.grid"):
        uwlab.evaluate(design)


def test_grid_rows_are_the_single_designs():
    design = uwlab.load_design(EXAMPLE)
    frame = uwlab.grid(
        design,
        {"operation.altitude_m": np.array([0.8, 1.6]), "water.type": ["jerlov-I", "jerlov-3C"]},
        outputs=["snr_db", "mean_dn"],
    )
    assert len(frame) == 4
    for (altitude, water), row in frame.iterrows():
        single = uwlab.evaluate(uwlab.load_design(EXAMPLE, operation__altitude_m=altitude, water__type=water))
        assert row["snr_db"] == pytest.approx(single["snr_db"], rel=1e-12)
        assert row["mean_dn"] == pytest.approx(single["mean_dn"], rel=1e-12)


def test_grid_to_xarray_is_gridded_by_the_axes():
    frame = uwlab.grid(
        uwlab.load_design(EXAMPLE), {"lens.f_number": [2, 2.8, 4], "operation.altitude_m": [1, 2]}, outputs=["mean_dn"]
    )
    cube = frame.to_xarray()["mean_dn"]
    assert cube.shape == (3, 2)
    # the response falls with the square of the f-number at a fixed altitude (no saturation here)
    ratio = (cube.sel({"lens.f_number": 2.0}) / cube.sel({"lens.f_number": 4.0})).values
    assert ratio == pytest.approx(4.0, rel=0.02)


def test_solve_sits_on_its_active_requirement():
    design = uwlab.load_design(EXAMPLE)
    best = uwlab.solve(
        design,
        free={"light.luminous_flux_lm": (100, 100000)},
        require=["snr_db >= 30"],
        minimize="light.luminous_flux_lm",
    )
    flux = float(best["light.luminous_flux_lm"].iloc[0])
    assert uwlab.evaluate(uwlab.load_design(EXAMPLE, light__luminous_flux_lm=flux))["snr_db"] >= 30 - 1e-9
    assert uwlab.evaluate(uwlab.load_design(EXAMPLE, light__luminous_flux_lm=0.99 * flux))["snr_db"] < 30
    assert best.attrs["answer"]["feasible"] is True


def test_solve_names_an_unmeetable_requirement():
    with pytest.raises(uwlab.Infeasible, match="snr_db >= 90"):
        uwlab.solve(
            uwlab.load_design(EXAMPLE),
            free={"light.luminous_flux_lm": (100, 1000)},
            require=["snr_db >= 90"],
            minimize="light.luminous_flux_lm",
        )
