"""`uwlab mtf IMAGE --json` on PNG and TIFF files, 8 and 16 bit, monochrome, RGB and a raw Bayer mosaic; and its
refusals (one line, exit 2)."""

from __future__ import annotations

import json
import os

import cv2
import numpy as np
import pytest
import tifffile
from scipy.special import erf

from tests.support.cli import one_line_error
from uwlab.cli.main import main

SIGMA_PX = 1.2
MTF50 = np.sqrt(np.log(2) / 2) / (np.pi * SIGMA_PX)


def edge(shape=(240, 160), angle_deg=6.0, full_scale=255, sigma=SIGMA_PX):
    y, x = np.mgrid[0 : shape[0], 0 : shape[1]]
    t = np.radians(angle_deg)
    d = ((x - shape[1] / 2) - np.tan(t) * (y - shape[0] / 2)) * np.cos(t)
    return full_scale * (0.1 + 0.7 * 0.5 * (1 + erf(d / (sigma * np.sqrt(2)))))


def run_json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize(
    "suffix,dtype,full",
    [(".png", np.uint8, 255), (".png", np.uint16, 65535), (".tif", np.uint16, 65535), (".tiff", np.uint8, 255)],
)
def test_mono_files_give_one_object_per_edge(tmp_path, capsys, suffix, dtype, full):
    path = tmp_path / f"edge{suffix}"
    image = np.round(edge(full_scale=full)).astype(dtype)
    if suffix == ".png":
        assert cv2.imwrite(str(path), image)
    else:
        tifffile.imwrite(path, image)
    edges = run_json(capsys, ["mtf", str(path), "--roi", "20,20,120,200", "--json"])
    assert len(edges) == 1
    (found,) = edges
    assert set(found) >= {"angle_deg", "mtf50_cy_per_px", "mtf_nyquist", "frequency_cy_per_px", "mtf"}
    assert found["angle_deg"] == pytest.approx(6.0, abs=0.1)
    assert found["mtf50_cy_per_px"] == pytest.approx(MTF50, rel=0.02)
    assert len(found["frequency_cy_per_px"]) == len(found["mtf"])


def test_rgb_planes_and_bayer_channels(tmp_path, capsys):
    planes = [edge(sigma=s) for s in (0.8, 1.2, 2.0)]
    rgb = np.round(np.stack(planes, axis=2)).astype(np.uint8)
    path = tmp_path / "rgb.png"
    assert cv2.imwrite(str(path), rgb[..., ::-1])  # OpenCV writes B, G, R
    for channel, sigma in zip(("red", "green", "blue"), (0.8, 1.2, 2.0), strict=True):
        (found,) = run_json(capsys, ["mtf", str(path), "--channel", channel, "--json"])
        assert found["mtf50_cy_per_px"] == pytest.approx(np.sqrt(np.log(2) / 2) / (np.pi * sigma), rel=0.03)
    mosaic = np.zeros((480, 320), np.uint16)
    big = [np.round(edge((480, 320), sigma=s, full_scale=4095)).astype(np.uint16) for s in (0.8, 1.2, 2.0)]
    mosaic[0::2, 0::2] = big[0][0::2, 0::2]  # RG: R G / G B
    mosaic[0::2, 1::2] = big[1][0::2, 1::2]
    mosaic[1::2, 0::2] = big[1][1::2, 0::2]
    mosaic[1::2, 1::2] = big[2][1::2, 1::2]
    raw = tmp_path / "raw.tif"
    tifffile.imwrite(raw, mosaic)
    (blue,) = run_json(capsys, ["mtf", str(raw), "--bayer", "RG", "--channel", "blue", "--json"])
    assert blue["mtf50_cy_per_px"] == pytest.approx(np.sqrt(np.log(2) / 2) / (np.pi * 2.0), rel=0.03)


def test_bad_inputs_are_one_line(tmp_path, capsys):
    flat = tmp_path / "flat.png"
    cv2.imwrite(str(flat), np.full((100, 100), 90, np.uint8))
    assert "no " in one_line_error(capsys, ["mtf", str(flat), "--json"])
    assert "no edge" in one_line_error(capsys, ["mtf", str(flat), "--roi", "10,10,60,60", "--json"])
    grid = tmp_path / "grid.png"
    cv2.imwrite(str(grid), np.round(edge(angle_deg=1.0)).astype(np.uint8))
    assert "pixel grid" in one_line_error(capsys, ["mtf", str(grid), "--roi", "20,20,120,200"])
    clipped = tmp_path / "clipped.png"
    cv2.imwrite(str(clipped), np.clip(edge() * 1.6, 0, 255).astype(np.uint8))
    assert "saturated" in one_line_error(capsys, ["mtf", str(clipped), "--roi", "20,20,120,200"])
    fifo = tmp_path / "fifo.png"
    os.mkfifo(fifo)
    assert "not a regular file" in one_line_error(capsys, ["mtf", str(fifo)])
    assert "not a regular file" in one_line_error(capsys, ["mtf", "/dev/zero"])
    text = tmp_path / "notes.png"
    text.write_text("not an image")
    assert "decode" in one_line_error(capsys, ["mtf", str(text)])
    assert "X,Y,W,H" in one_line_error(capsys, ["mtf", str(grid), "--roi", "1,2,3"])
    assert "within" in one_line_error(capsys, ["mtf", str(grid), "--roi", "100,100,500,500"])
    assert "--bayer" in one_line_error(capsys, ["mtf", str(grid), "--channel", "red"])
