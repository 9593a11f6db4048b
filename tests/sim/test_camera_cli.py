"""`uwlab devices` and `uwlab grab` with the sim backend (in-process CLI calls)."""

from __future__ import annotations

import json
from pathlib import Path

import genicam
import pytest
import tifffile

from uwlab.cli.main import main

VIKY = str(Path(genicam.__file__).parent / "viky.cti")


def run_json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_devices_lists_every_backend(capsys):
    devices = run_json(capsys, ["devices", "--json", "--cti", VIKY])
    backends = {d["backend"] for d in devices}
    assert {"sim", "harvesters"} <= backends
    assert all(set(d) == {"backend", "id", "vendor", "model", "serial"} for d in devices)
    assert any(d["id"] == "VikyTL_DEV_red" for d in devices)


def test_devices_reports_missing_producer_without_failing(capsys, monkeypatch):
    monkeypatch.delenv("GENICAM_GENTL64_PATH", raising=False)
    assert main(["devices"]) == 0
    captured = capsys.readouterr()
    assert "harvesters backend unavailable" in captured.err and "sim0" in captured.out


def test_grab_json_keys_roi_and_settings(capsys):
    doc = run_json(
        capsys,
        [
            "grab",
            "--frames",
            "3",
            "--roi",
            "1000,900,128,64",
            "--exposure-us",
            "100",
            "--gain-db",
            "3",
            "--pixel-format",
            "Mono12p",
            "--json",
        ],
    )
    assert doc["device"]["backend"] == "sim" and doc["device"]["model"].startswith("SimCam-")
    keys = {
        "frame_id",
        "timestamp_ns",
        "width",
        "height",
        "pixel_format",
        "exposure_us",
        "gain_db",
        "mean",
        "std",
        "min",
        "max",
        "saturated_fraction",
        "clip_level_dn",
        "clip_source",
    }
    assert len(doc["frames"]) == 3 and all(set(f) == keys for f in doc["frames"])
    f = doc["frames"][0]
    assert (f["width"], f["height"], f["pixel_format"], f["exposure_us"], f["gain_db"]) == (
        128,
        64,
        "Mono12p",
        100.0,
        3.0,
    )
    assert f["min"] <= f["mean"] <= f["max"] and f["std"] > 0 and 0.0 <= f["saturated_fraction"] <= 1.0


def test_grab_long_exposure_saturates(capsys):
    doc = run_json(capsys, ["grab", "--roi", "1100,950,64,64", "--exposure-us", "1000000", "--gain-db", "20", "--json"])
    assert doc["frames"][0]["saturated_fraction"] == 1.0


def test_grab_save_writes_tiff_with_settings_and_never_overwrites(capsys, tmp_path):
    argv = ["grab", "--frames", "2", "--roi", "0,0,32,16", "--save", str(tmp_path), "--json"]
    run_json(capsys, argv)
    run_json(capsys, argv)
    files = sorted(p.name for p in tmp_path.iterdir())
    assert files == ["frame-000001-1.tiff", "frame-000001.tiff", "frame-000002-1.tiff", "frame-000002.tiff"]
    with tifffile.TiffFile(tmp_path / "frame-000001.tiff") as tif:
        image = tif.asarray()
        meta = tif.shaped_metadata[0]
    assert image.shape == (16, 32)
    assert meta["settings"]["width"] == 32 and meta["device"]["backend"] == "sim" and meta["frame_id"] == 1


@pytest.mark.parametrize(
    "argv,message",
    [
        (["grab", "--exposure-us", "1"], "exposure_us = 1.0: out of range for ExposureTime"),
        (["grab", "--pixel-format", "RGB8"], "pixel_format = 'RGB8'"),
        (["grab", "--device", "cam9"], "unknown device id 'cam9'; found: sim0"),
        (["grab", "--roi", "1,2,3"], "roi = '1,2,3'"),
    ],
)
def test_grab_bad_input_is_one_line_exit_2(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
