"""Port calibration on simulated ChArUco images (`uwlab sim charuco` → `uwlab port calibrate`): the simulated
truth (decentring, port distance and tilt, focal ratio) is written only to the images' sidecar, which the
calibration never reads. Targets: decentring within 0.2 mm, f_uw/f_air within 0.5 %, RMS below 0.3 px."""

import json

import cv2
import numpy as np
import pytest

from tests.support.paths import ROOT
from uwlab.cli.main import main
from uwlab.experiments.port.board import CharucoBoard, detect
from uwlab.experiments.port.simulate import camera_of, port_in
from uwlab.model.design import load_design
from uwlab.model.port_field import focal_ratio, port_of

DOME = ROOT / "configs" / "design" / "dome-8mm.toml"
DECENTER_MM = (1.5, -1.0, 2.0)
FLAT = ["--set", "housing.port='flat'", "--set", "housing.flat_thickness_mm=8"]
FLAT_TRUTH = ["--set", "housing.flat_air_gap_mm=6", "--set", "housing.flat_tilt_deg=[1.5, -1.0]"]
DOME_VIEWS = ("16", "3")  # poses, downsample: over 8 seeds σ = 0.035–0.057 mm and the largest error 0.12 mm
FLAT_VIEWS = ("12", "4")


def cli(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def render(capsys, out, medium, seed, views, *settings):
    poses, downsample = views
    code, _, err = cli(
        capsys,
        "sim",
        "charuco",
        DOME,
        "--medium",
        medium,
        "--poses",
        poses,
        "--seed",
        seed,
        "--downsample",
        downsample,
        "--lens-k1",
        "-0.05",
        "--out",
        out,
        *settings,
    )
    assert code == 0, err


@pytest.fixture(scope="module")
def dome_sets(tmp_path_factory):
    root = tmp_path_factory.mktemp("dome")
    capsys = _NoCapture()
    decenter = "housing.dome_decenter_mm=" + ",".join(str(v) for v in DECENTER_MM)
    render(capsys, root / "air", "air", 1, DOME_VIEWS, "--set", decenter)
    render(capsys, root / "water", "water", 2, DOME_VIEWS, "--set", decenter)
    return root


@pytest.fixture(scope="module")
def flat_sets(tmp_path_factory):
    """A flat port, the lens refocused underwater (focal length +1 %)."""
    root = tmp_path_factory.mktemp("flat")
    capsys = _NoCapture()
    render(capsys, root / "air", "air", 3, FLAT_VIEWS, *FLAT, *FLAT_TRUTH)
    render(capsys, root / "water", "water", 4, FLAT_VIEWS, *FLAT, *FLAT_TRUTH, "--set", "lens.focal_length_mm=8.08")
    return root


class _NoCapture:
    """Module fixtures cannot use capsys: the CLI's output is not needed there."""

    def readouterr(self):
        return "", ""


def test_rendered_corners_lie_where_the_exact_optics_put_them(dome_sets):
    """Detected corners against the true poses of the sidecar projected through the true port: no bias, small
    scatter (the renderer is exact up to the detector)."""
    sidecar = json.loads((dome_sets / "water" / "charuco.json").read_text())
    assert sidecar["port"]["decenter_mm"] == pytest.approx(list(DECENTER_MM))
    board = CharucoBoard.from_dict(sidecar["board"])
    design = load_design(DOME, {"housing.dome_decenter_mm": list(DECENTER_MM)})
    port = port_in(design, "water")
    lens, _, _ = camera_of(design, sidecar["camera"]["downsample"], sidecar["camera"]["distortion"][0])
    errors = []
    for pose in sidecar["poses"]:
        found = detect(board, cv2.imread(str(dome_sets / "water" / pose["image"]), cv2.IMREAD_GRAYSCALE))
        rotation = cv2.Rodrigues(np.array(pose["rvec"]))[0]
        truth = lens.pixels(port.project(board.corners_m[found.ids] @ rotation.T + np.array(pose["tvec_m"])))
        errors.append(found.pixels - truth)
    errors = np.concatenate(errors)
    assert len(errors) > 250
    assert np.all(np.abs(errors.mean(axis=0)) < 0.02)
    assert np.sqrt(np.mean(np.sum(errors**2, axis=1))) < 0.12


def test_dome_decentring_and_focal_ratio_are_recovered(capsys, dome_sets):
    code, out, err = cli(
        capsys,
        "port",
        "calibrate",
        dome_sets / "air",
        dome_sets / "water",
        "--port",
        "dome",
        "--config",
        DOME,
        "--json",
    )
    assert code == 0, err
    result = json.loads(out)
    for key in ("port", "decenter_mm", "decenter_mm_std", "f_ratio", "f_ratio_std", "rms_px", "centred_enough"):
        assert key in result
    for axis, truth in zip("xyz", DECENTER_MM, strict=True):
        error = result["decenter_mm"][axis] - truth
        assert abs(error) < 0.2, (axis, error)
        assert 0.01 < result["decenter_mm_std"][axis] < 0.08
    true_ratio = focal_ratio(port_of(load_design(DOME, {"housing.dome_decenter_mm": list(DECENTER_MM)})))
    assert result["f_ratio"] == pytest.approx(true_ratio, rel=0.005)
    assert abs(result["f_ratio"] - true_ratio) < 4 * result["f_ratio_std"] + 1e-4
    assert result["rms_px"] < 0.3 and result["air"]["rms_px"] < 0.3
    assert result["centred_enough"] is False and result["induced_distortion_px"] > result["max_distortion_px"]
    code, out, _ = cli(
        capsys,
        "port",
        "calibrate",
        dome_sets / "air",
        dome_sets / "water",
        "--port",
        "dome",
        "--config",
        DOME,
        "--max-distortion-px",
        "50",
    )
    verdict = next(line for line in out.splitlines() if line.startswith("centred enough"))
    assert code == 0 and verdict.split() == ["centred", "enough", "(≤", "50", "px)", "yes"]


def test_flat_port_distance_tilt_and_refocused_focal_ratio(capsys, flat_sets):
    code, out, err = cli(
        capsys,
        "port",
        "calibrate",
        flat_sets / "air",
        flat_sets / "water",
        "--port",
        "flat",
        "--config",
        DOME,
        *FLAT,
        "--focus",
        "refocused",
        "--json",
    )
    assert code == 0, err
    result = json.loads(out)
    true_port = port_of(
        load_design(
            DOME,
            {
                "housing.port": "flat",
                "housing.flat_thickness_mm": 8,
                "housing.flat_air_gap_mm": 6,
                "housing.flat_tilt_deg": [1.5, -1.0],
            },
        )
    )
    true_ratio = 8.08 / 8.0 * focal_ratio(true_port)
    assert result["f_ratio"] == pytest.approx(true_ratio, rel=0.005)
    assert result["rms_px"] < 0.3
    assert abs(result["port_distance_mm"] - 6.0) < 4 * result["port_distance_mm_std"]
    for axis, truth in zip("xy", (1.5, -1.0), strict=True):
        assert abs(result["tilt_deg"][axis] - truth) < max(4 * result["tilt_deg_std"][axis], 0.1)
    assert "decenter_mm" not in result and "centred_enough" not in result


def test_too_few_corners_is_a_one_line_refusal(capsys, dome_sets, tmp_path):
    other = tmp_path / "board.toml"
    other.write_text('squares = [7, 5]\nsquare_mm = 40\nmarker_mm = 30\ndictionary = "DICT_4X4_50"\n')
    code, out, err = cli(
        capsys,
        "port",
        "calibrate",
        dome_sets / "air",
        dome_sets / "water",
        "--port",
        "dome",
        "--config",
        DOME,
        "--board",
        other,
    )
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "ChArUco corners" in err and "DIR_AIR" in err and "Traceback" not in err
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = cli(capsys, "port", "calibrate", dome_sets / "air", empty, "--port", "dome", "--config", DOME)
    assert code == 2 and "DIR_WATER" in err and "no images" in err


def test_sim_charuco_never_overwrites_a_recording(capsys, dome_sets):
    before = sorted(p.name for p in (dome_sets / "air").iterdir())
    code, _, err = cli(capsys, "sim", "charuco", DOME, "--medium", "air", "--poses", "1", "--out", dome_sets / "air")
    assert code == 2 and "not empty" in err
    assert sorted(p.name for p in (dome_sets / "air").iterdir()) == before


def test_real_image_path_reads_16_bit_tiffs_as_grab_saves_them(capsys, dome_sets, tmp_path):
    """The same views as Mono16 TIFFs with grab's metadata: every view used, the same targets met."""
    import tifffile

    for medium in ("air", "water"):
        (tmp_path / medium).mkdir()
        for number, png in enumerate(sorted((dome_sets / medium).glob("*.png"))):
            image = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE).astype(np.uint16) << 8
            tifffile.imwrite(
                tmp_path / medium / f"frame-{number:06d}.tiff",
                image,
                metadata={"pixel_format": "Mono16", "settings": {"exposure_us": 10000.0}},
            )
    code, out, err = cli(
        capsys, "port", "calibrate", tmp_path / "air", tmp_path / "water", "--port", "dome", "--config", DOME, "--json"
    )
    assert code == 0, err
    result = json.loads(out)
    assert result["water"]["views"] == result["air"]["views"] == int(DOME_VIEWS[0])
    for axis, truth in zip("xyz", DECENTER_MM, strict=True):
        assert abs(result["decenter_mm"][axis] - truth) < 0.2
