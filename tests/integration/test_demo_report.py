"""The main job end to end on the simulated rig (the tank world, the extended model), and the report and fit
commands on its outputs."""

import json

import pytest

from uwlab.cli.main import main
from uwlab.experiments.dataset import Dataset
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
    # each camera was characterised on the simulated EMVA bench first, and fitted with its measured response
    # curve: the sensors' charge compression is gone from the residuals; the light's warm-up drift during the
    # campaign's first sweep (the tank world's, which no model here has) is in the spectrometer's readings and
    # the fit follows it there, so no sweep's residuals drift
    fit = json.loads((demo / "fit" / "summary.json").read_text())
    assert set(fit["sensors"]) == {"imx250m", "icx285alm"}
    assert all(text.startswith("characterised: ") for text in fit["sensors"].values())
    assert all((demo / "emva" / camera / f"{camera}.toml").is_file() for camera in fit["sensors"])
    assert all(check["passed"] for check in summary["checks"]) and summary["model_adequate"]
    first = Dataset.open(demo / "dataset").points().query("sweep_id == 'imx250-no-lens' and kind != 'dark'")
    readings = first.sort_values("point_index")["irradiance_w_m2"].to_numpy(float)
    assert readings[:3].mean() / readings[-3:].mean() - 1 > 0.005  # the light settled by more than 0.5 %
    drift = {
        r["sweep_id"]: r["trend_end_percent"] - r["trend_start_percent"] for r in fit["posterior_predictive_checks"]
    }
    assert len(drift) == 6 and max(abs(v) for v in drift.values()) < 0.2
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
        "✔ Adequate:",
        "within-configuration trend",
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


@pytest.mark.parametrize(
    ("sensor", "expected"),
    [
        ("imx250m=/no/such/profile.toml", "no such profile or `uwlab emva characterize` folder"),
        ("nocam=emva/imx250m", "no camera 'nocam' in this dataset"),
        ("emva/imx250m", "name the camera: CAMERA=FROM"),
        ("imx250m=PROFILE", "has no [response] curve"),
    ],
)
def test_fit_sensor_bad_input_is_one_line(demo, tmp_path, capsys, sensor, expected):
    sensor = sensor.replace("emva/", f"{demo}/emva/").replace("PROFILE", str(ROOT / "configs/sensors/imx250m.toml"))
    assert main(["fit", str(demo / "dataset"), "--out", str(tmp_path / "fit"), "--sensor", sensor]) == 2
    err = capsys.readouterr().err
    assert expected in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "fit").exists()


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


def test_the_report_and_the_datasheet_at_1400_px_keep_every_figure_inside_and_legible(demo, tmp_path):
    # the rules of uwlab.experiments.figures: text of p points in a figure saved at d dpi is p·d/72 px, so it stays
    # ≥ 11 px when the figure is shown at ≥ 11·72/(p·d) of its pixel size: the report's figures (90 dpi, ≥ 11 pt)
    # at ≥ 0.8, the datasheet's (110 dpi, ≥ 9.5 pt) at ≥ 0.758; nothing may stick out of the page
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By

    options = Options()
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"):
        options.add_argument(argument)
    options.binary_location = "/usr/bin/chromium"
    browser = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
    try:
        browser.set_window_size(1400, 1000)
        pages = {
            demo / "report.html": 11 * 72 / (11 * 90),
            demo / "emva" / "imx250m" / "datasheet.html": 11 * 72 / (9.5 * 110),
        }
        for page, least in pages.items():
            browser.get(page.as_uri())
            assert browser.execute_script("return document.documentElement.scrollWidth <= window.innerWidth"), page
            images = browser.find_elements(By.TAG_NAME, "img")
            assert images
            for img in images:
                box = browser.execute_script(
                    "const r = arguments[0].getBoundingClientRect();"
                    "return [r.left, r.right, arguments[0].naturalWidth, window.innerWidth];",
                    img,
                )
                left, right, natural, width = box
                assert left >= 0 and right <= width, (page.name, box)
                if natural > 600 and img.is_displayed():  # the figures, not icons or folded <details>
                    assert (right - left) / natural >= least, (page.name, box)
            browser.save_screenshot(str(tmp_path / f"{page.stem}.png"))
    finally:
        browser.quit()
