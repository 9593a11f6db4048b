"""`uwlab report DIR` on what the other commands write: the matching report, or one line saying what DIR holds."""

from __future__ import annotations

import pytest

from tests.support.paths import CONFIGS, EXAMPLE
from uwlab.cli.main import main


@pytest.fixture(scope="module")
def bench_dataset(tmp_path_factory):
    """The shipped EMVA 1288 photon-transfer plan swept on the simulated bench."""
    out = tmp_path_factory.mktemp("bench") / "emva-ds"
    assert main(["sweep", str(CONFIGS / "plans" / "emva-photon-transfer.toml"), "--sim", "--out", str(out)]) == 0
    return out


def test_a_bench_dataset_reports_its_bench_and_names_the_datasheet_command(bench_dataset, capsys):
    assert main(["report", str(bench_dataset), "--out", str(bench_dataset.parent / "r.html")]) == 0
    html = (bench_dataset.parent / "r.html").read_text()
    assert "EMVA 1288 bench" in html and "uwlab emva characterize" in html
    assert "Traceback" not in capsys.readouterr().err


def test_with_its_characterisation_the_report_includes_the_datasheet(bench_dataset, capsys):
    campaign = bench_dataset.parent
    assert main(["emva", "characterize", str(bench_dataset), "--out", str(campaign / "emva")]) == 0
    assert main(["report", str(campaign), "--out", str(campaign / "all.html")]) == 0
    html = (campaign / "all.html").read_text()
    assert "uwlab emva characterize" not in html and "EMVA 1288" in html


@pytest.mark.parametrize("make", ["empty", "design plots"])
def test_a_folder_without_results_is_one_line(tmp_path, capsys, make):
    if make == "design plots":
        assert main(["design", str(EXAMPLE), "--plot", str(tmp_path)]) == 0
        capsys.readouterr()
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no dataset, calibration or EMVA characterisation found" in err
