"""The main job end to end on the simulated rig (the tank world, the extended model), and the report and fit
commands on its outputs."""

import json
import re
from html import escape as html_escape

import cv2
import emcee
import numpy as np
import pyarrow
import pytest
import scipy

import uwlab
from uwlab.cli.main import main
from uwlab.experiments.dataset import Dataset
from tests.support.chromium import chromium
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


def test_a_fit_that_fails_part_way_leaves_nothing_and_runs_again(demo, tmp_path, monkeypatch):
    """The whole-data outputs are written while the folds run; when the folds then fail, they are removed, so the
    same command runs again into the same folder (a folder with a calibration in it is refused)."""
    from uwlab.errors import UwlabError
    from uwlab.experiments.calibration import pipeline
    from uwlab.experiments.calibration.output import OUTPUT_FILES

    class FoldsFail:
        @staticmethod
        def of(folds):
            assert (out / "corner.png").is_file()  # written meanwhile
            raise UwlabError("a fold failed")

    out = tmp_path / "fit"
    quick = {"dataset_dir": demo / "dataset", "config_path": None, "out": out, "held_out": 2, "model": "paper"}
    quick["sampler"] = {"max_steps": 1000, "chunk_steps": 500}
    with monkeypatch.context() as patch:
        patch.setattr(pipeline, "CrossValidation", FoldsFail)
        with pytest.raises(UwlabError, match="a fold failed"):
            pipeline.calibrate(**quick)
    assert not [name for name in OUTPUT_FILES if (out / name).exists()]
    calibration = pipeline.calibrate(**quick)
    assert all((out / name).is_file() for name in OUTPUT_FILES)
    assert len(calibration.summary["folds"]) == 2


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
    from selenium.webdriver.common.by import By

    browser = chromium(tmp_path / "chromium-profile")
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


def test_the_report_names_the_versions_and_the_cpu(demo):
    html = (demo / "report.html").read_text()
    made_with = html[html.index("<h2>Provenance</h2>") :]
    for what in ("this report", f"dataset {demo / 'dataset'}", f"fit {demo / 'fit'}", "EMVA 1288 characterisation"):
        assert what in made_with
    metadata = Dataset.open(demo / "dataset").metadata["provenance"]
    for named in (
        f"uwlab {uwlab.__version__}",
        f"numpy {np.__version__}",
        f"scipy {scipy.__version__}",
        f"emcee {emcee.__version__}",
        f"pyarrow {pyarrow.__version__}",
        f"OpenCV {cv2.__version__}",
        f"CPU {html_escape(metadata['cpu'])}",
        "BLAS ",
    ):
        assert named in made_with, named


# README: "equal seeds give equal numbers" on one machine; across machines with the locked versions the fit's
# numbers agree within the Monte Carlo error of the posterior. A README number and the demo's may each be off by
# their Monte Carlo error (so √2 of it between them); MC_SIGMAS of those, plus half the last printed digit.
MC_SIGMAS = 4


def readme_demo_block() -> list[str]:
    """The lines of the README's ``` block after "equal seeds give equal numbers" (`uwlab demo`'s output)."""
    text = (ROOT / "README.md").read_text()
    after = text[text.index("equal seeds give equal numbers") :]
    start = after.index("```\n") + 4
    return after[start : after.index("```", start)].splitlines()


def half_digit(text: str) -> float:
    """Half a unit in the last printed digit of the number `text` ("0.8058" → 0.00005, "1.64" → 0.005)."""
    decimals = len(text.split(".")[1]) if "." in text else 0
    return 0.5 * 10.0**-decimals


def parse_readme_summary(lines: list[str]) -> dict:
    parameter = re.compile(r"^(\S+)\s+(\S+)\s+(\S+)\s+\[(\S+), (\S+)\]$")
    coverage = re.compile(
        r"^held-out points inside their 95 % bands: (\d+) % "
        r"\(median half-width ±(\S+) % for median errors of (\S+) %\)$"
    )
    held_out = re.compile(r"^\s+(\S+)\s+held out: median error (\S+) %, (\d+) % inside$")
    found: dict = {"verdict": lines[0], "parameters": {}, "held_out": {}}
    for line in lines[2:]:
        if m := parameter.match(line):
            found["parameters"][m[1]] = {"truth": m[2], "median": m[3], "p2_5": m[4], "p97_5": m[5]}
        elif m := coverage.match(line):
            found["coverage"] = {"inside": m[1], "half_width": m[2], "error": m[3]}
        elif m := held_out.match(line):
            found["held_out"][m[1]] = {"error": m[2], "inside": m[3]}
        elif line.startswith("converged: "):
            found["converged"] = line.removeprefix("converged: ")
    return found


def test_the_readme_demo_numbers_agree_with_the_demo_within_their_monte_carlo_error(demo):
    import arviz as az
    import pandas as pd

    from uwlab.experiments.calibration.validation import MAX_PREDICTIVE_SAMPLES

    readme = parse_readme_summary(readme_demo_block())
    summary = json.loads((demo / "summary.json").read_text())
    verdict = "adequate" if summary["model_adequate"] else "NOT adequate"
    assert readme["verdict"] == f"{summary['model']} model in the {summary['world']} world: {verdict}"
    assert readme["converged"] == str(summary["converged"])

    # the parameters: arviz's Monte Carlo standard errors of the median and of the 2.5 and 97.5 % quantiles
    posterior = az.from_netcdf(demo / "fit" / "posterior.nc")
    mcse = {
        "median": az.mcse(posterior, method="median"),
        "p2_5": az.mcse(posterior, method="quantile", prob=0.025),
        "p97_5": az.mcse(posterior, method="quantile", prob=0.975),
    }
    assert set(readme["parameters"]) == set(summary["parameters"])
    for name, printed in readme["parameters"].items():
        fitted = summary["parameters"][name]
        truth = fitted["truth"]
        assert printed["truth"] == ("—" if truth is None else f"{truth:.4g}"), name
        for key, mc in mcse.items():
            tolerance = MC_SIGMAS * np.sqrt(2) * float(mc[name]) + half_digit(printed[key])
            assert abs(float(printed[key]) - fitted[key]) <= tolerance, (
                name,
                key,
                printed[key],
                fitted[key],
                tolerance,
            )

    # the held-out predictions: the median of ≤ MAX_PREDICTIVE_SAMPLES draws from a fold's posterior (itself a
    # chain of about the main fit's effective size) moves a configuration's predicted level by 1.2533·σ·√(1/n + 1/ESS)
    # (the median's standard error, σ from the predicted 95 % band); a band edge (a 2.5 or 97.5 % quantile) by
    # 2.67·σ·√(…) (√(p(1−p))/φ(1.96))
    ess = float(az.ess(posterior, method="bulk").to_array().min())
    root_n = np.sqrt(1 / MAX_PREDICTIVE_SAMPLES + 1 / ess)
    points = pd.read_parquet(demo / "fit" / "heldout.parquet")
    level_sigma = (points["predicted_p97_5"] - points["predicted_p2_5"]) / 3.92 / points["predicted_median"]
    edge_sigma = (points["observed_p97_5"] - points["observed_p2_5"]) / 3.92 / points["predicted_median"]
    level_mc = MC_SIGMAS * np.sqrt(2) * 1.2533 * level_sigma * root_n  # relative
    edge_mc = MC_SIGMAS * np.sqrt(2) * 2.67 * edge_sigma * root_n * points["predicted_median"]  # DN
    near_edge = (np.abs(points["measured_dn"] - points["observed_p2_5"]) <= edge_mc) | (
        np.abs(points["measured_dn"] - points["observed_p97_5"]) <= edge_mc
    )
    rows = {row["sweep_id"]: row for row in summary["cross_configuration"]}
    assert list(readme["held_out"]) == list(rows)
    for sweep_id, printed in readme["held_out"].items():
        mine = points["sweep_id"] == sweep_id
        tolerance = 100 * level_mc[mine].max() + half_digit(printed["error"])
        error = 100 * rows[sweep_id]["median_abs_rel_error"]
        assert abs(float(printed["error"]) - error) <= tolerance, (sweep_id, printed["error"], error, tolerance)
        flips = 100 * (near_edge[mine].sum() + 0.5) / mine.sum()  # a point within MC error of an edge may flip
        assert abs(float(printed["inside"]) - 100 * rows[sweep_id]["inside_95"]) <= flips, sweep_id
    coverage = summary["predictive_coverage"]
    flips = 100 * (near_edge.sum() + 0.5) / len(points)
    assert abs(float(readme["coverage"]["inside"]) - 100 * coverage["held_out_inside_95"]) <= flips
    half_width_mc = 100 * (edge_mc / points["predicted_median"]).max()
    for key, value in (("half_width", "held_out_half_width_percent"), ("error", "held_out_error_percent")):
        printed = readme["coverage"][key]
        tolerance = (half_width_mc if key == "half_width" else 100 * level_mc.max()) + half_digit(printed)
        assert abs(float(printed) - coverage[value]) <= tolerance, (key, printed, coverage[value], tolerance)
