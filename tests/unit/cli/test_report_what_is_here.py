"""`uwlab report DIR` on a folder with nothing to report says in one line what the folder holds and which command
takes it (exit 2, no traceback)."""

from __future__ import annotations

import shutil

import pytest

from tests.support.paths import CONFIGS
from uwlab.cli.main import main


@pytest.mark.parametrize(
    ("fill", "expected"),
    [
        (lambda d: shutil.copy(CONFIGS / "plans" / "tank-exposure-sweep.toml", d), "it holds a sweep plan: run it"),
        (lambda d: shutil.copy(CONFIGS / "design" / "example.toml", d), "it holds configs: a design"),
        (lambda d: (d / "frame.tiff").write_bytes(b"II*\x00"), "it holds images"),
        (lambda d: None, "it holds no uwlab output"),
    ],
)
def test_nothing_to_report_is_one_line_naming_the_command(tmp_path, capsys, fill, expected):
    folder = tmp_path / "folder"
    folder.mkdir()
    fill(folder)
    assert main(["report", str(folder), "--out", str(tmp_path / "r.html")]) == 2
    err = capsys.readouterr().err
    assert "no dataset, calibration or EMVA characterisation found" in err and expected in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "r.html").exists()
