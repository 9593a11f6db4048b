"""The main job end to end on the simulated rig (the tank world, the extended model), and the report and fit
commands on its outputs."""

import json

import pytest

from uwlab.cli.main import main
from tests.support.paths import ROOT


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "campaign"
    assert main(["demo", "--out", str(out)]) == 0
    return out


def test_demo_recovers_the_simulated_truth(demo):
    summary = json.loads((demo / "summary.json").read_text())
    assert summary["converged"]
    assert (summary["world"], summary["model"]) == ("tank", "extended")
    # the tank world's sensors compress charge near full well (1 %), which the fitted chain does not model: the
    # trend check names it, and it is the only check that fails
    failed = [check for check in summary["checks"] if not check["passed"]]
    assert [check["name"] for check in failed] == ["within-configuration trend"] and not summary["model_adequate"]
    assert failed[0]["detail"].startswith("unmodelled response non-linearity: the residuals drift with exposure")
    for row in summary["posterior_predictive_checks"]:  # charge compression: residuals fall with exposure
        assert row["trend_end_percent"] < row["trend_start_percent"]
    coverage = summary["predictive_coverage"]
    assert coverage["held_out_inside_95"] >= 0.9 and set(coverage["per_configuration"]) == {
        "imx250-no-lens",
        "imx250-30mm-f2",
        "imx250-12mm-f4",
        "icx285-no-lens",
        "icx285-30mm-f2",
        "icx285-12mm-f4",
    }
    for name, p in summary["parameters"].items():
        assert set(p) == {"truth", "median", "p2_5", "p16", "p84", "p97_5", "tau"}
        assert p["p2_5"] <= p["p16"] <= p["median"] <= p["p84"] <= p["p97_5"]
        if p["truth"] is not None:
            assert p["p2_5"] <= p["truth"] <= p["p97_5"], name
    assert summary["parameters"]["light_efficiency"]["truth"] == pytest.approx(0.8)
    held_out = summary["cross_configuration"]
    assert len(held_out) == 6 and all(r["median_abs_rel_error"] < 0.05 for r in held_out)


def test_report_is_self_contained(demo):
    html = (demo / "report.html").read_text()
    for heading in (
        "Adequate:",
        "Set-up",
        "Checks",
        "Measured against predicted",
        "predicted by a fit that did not see it",
        "Posterior",
        "Spectra",
        "Provenance",
    ):
        assert heading in html
    assert html.index("Adequate:") < html.index("Set-up")  # the verdict first
    assert "none (bare sensor)" in html and "IMX250M · 30 mm f/2" in html
    assert html.count("data:image/png;base64,") >= 4 and 'src="http' not in html and 'src="/' not in html


def test_report_refuses_to_overwrite_and_fit_refuses_existing_output(demo, capsys):
    assert main(["report", str(demo)]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["report", str(demo), "--out", str(demo / "again.html"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["report"].endswith("again.html")
    assert main(["fit", str(demo / "dataset"), "--out", str(demo / "fit")]) == 2
    assert "already holds a calibration" in capsys.readouterr().err


def test_fit_with_a_config_file_and_bad_configs(demo, tmp_path, capsys):
    out = tmp_path / "fit"
    assert (
        main(
            [
                "fit",
                str(demo / "dataset"),
                "--config",
                str(ROOT / "configs/fit/default.toml"),
                "--out",
                str(out),
                "--json",
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert [f["trained_on"] for f in summary["folds"]] == [["imx250-30mm-f2"]] and summary["converged"]
    bad = tmp_path / "bad.toml"
    bad.write_text('[parameters.light_efficency]\nkind = "lognormal"\nmedian = 1.0\nsigma = 0.5\n')
    assert main(["fit", str(demo / "dataset"), "--config", str(bad), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "parameters.light_efficency" in err
    assert main(["demo", "--out", str(demo)]) == 2
    assert "not empty" in capsys.readouterr().err
