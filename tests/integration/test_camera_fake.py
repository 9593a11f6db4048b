"""The backends' own test cameras as first-class devices: Aravis's fake camera ``Fake_1`` and the GenTL test producer
of the genicam wheel, found without paths.

Truth for ``Fake_1`` is Aravis's image generator (``arv_fake_camera_diagonal_ramp`` in Aravis 0.8's
``src/arvfakecamera.c``), which uwlab does not contain: pixel (x, y) of frame f is the diagonal ramp
``(x + y + f) mod 255`` (Mono8; ``256 (x + y + f) mod 65535`` in Mono16) times ``1 + GainRaw + log10(t_exp / 10 ms)``,
truncated to the format's range.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from uwlab.cli.main import main
from uwlab.drivers.camera import Policy, discover, open_camera
from uwlab.drivers.camera.aravis_backend import Aravis
from uwlab.drivers.camera.harvesters_backend import cti_files, bundled_producers
from uwlab.errors import ConfigError, DeviceError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.rigs import HardwareRig
from uwlab.experiments.acquisition.sweep import SweepRunner
from uwlab.experiments.dataset import Dataset
from tests.support.plans import write_plan

FAST = Policy(timeout_s=3.0, reconnect_attempts=1, reconnect_delay_s=0.1)


def fake_ramp(frame_id: int, width: int, height: int, exposure_us: float, gain_raw: int, top: int = 255) -> np.ndarray:
    """Aravis's fake image (module docstring); ``top`` 255 for Mono8, 65535 for Mono16 (ramp step 256)."""
    step = 1 if top == 255 else 256
    y, x = np.mgrid[0:height, 0:width]
    scale = 1.0 + gain_raw + math.log10(exposure_us / 10000.0)
    return np.clip(np.trunc(((step * (x + y + frame_id)) % top) * scale), 0, top)


def run_json(capsys, argv):
    assert main(argv) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


def test_devices_fake_lists_aravis_fake_and_the_gentl_test_producer(capsys, monkeypatch):
    monkeypatch.delenv("GENICAM_GENTL64_PATH", raising=False)
    listed = {(d["backend"], d["id"]) for d in run_json(capsys, ["devices", "--fake", "--json"])}
    assert {("aravis", "Fake_1"), ("harvesters", "VikyTL_DEV_red"), ("sim", "sim0")} <= listed
    plain = {(d["backend"], d["id"]) for d in run_json(capsys, ["devices", "--json"])}
    assert ("aravis", "Fake_1") not in plain and not any(backend == "harvesters" for backend, _ in plain)


def test_the_test_producer_is_found_in_the_genicam_package(monkeypatch):
    monkeypatch.delenv("GENICAM_GENTL64_PATH", raising=False)
    producers = bundled_producers()
    assert [p.name for p in producers] == ["viky.cti"] and producers[0].is_file()
    assert cti_files(fake=True) == producers
    assert cti_files([str(producers[0])], fake=True) == producers  # named twice, loaded once
    found, unavailable = discover(("harvesters",), fake=True)
    assert "harvesters" not in unavailable and len(found) == 3


def test_first_camera_is_never_the_fake_one_unless_asked():
    with open_camera("aravis", None, fake=True, policy=FAST) as cam:
        assert cam.info.device_id == "Fake_1"
    # the GigE servers other test workers start on the loopback are cameras too: look only where there is none
    Aravis.disable_interface("GigEVision")
    try:
        with pytest.raises(DeviceError, match="aravis: no camera found"):
            open_camera("aravis", None, policy=FAST)
    finally:
        Aravis.enable_interface("GigEVision")


@pytest.mark.parametrize(
    "exposure_us,gain_db,gain_raw", [(10000.0, 0.0, 0), (10000.0, 6.0, 1), (100000.0, 0.0, 0), (3000.0, 9.6, 2)]
)
def test_fake_frames_are_arvis_diagonal_ramp(exposure_us, gain_db, gain_raw):
    with open_camera("aravis", "Fake_1", policy=FAST) as cam:
        assert cam.profile.name == "aravis-fake" and cam.info.vendor == "Aravis" and cam.info.serial == "1"
        cam.pixel_format = "Mono8"
        cam.set_roi(0, 0, 300, 40)
        cam.exposure_us, cam.gain_db = exposure_us, gain_db
        assert cam.transport.get("GainRaw") == gain_raw and cam.transport.get("ExposureTimeAbs") == exposure_us
        assert cam.gain_db == pytest.approx(20 * math.log10(1 + gain_raw))
        frames = cam.acquire(2)
    for frame in frames:
        assert frame.image.shape == (40, 300) and frame.image.dtype == np.uint8
        np.testing.assert_array_equal(frame.image, fake_ramp(frame.frame_id, 300, 40, exposure_us, gain_raw))


def test_fake_mono16_and_gain_limits():
    with open_camera("aravis", "Fake_1", policy=FAST) as cam:
        cam.pixel_format = "Mono16"
        cam.set_roi(0, 0, 64, 8)
        cam.exposure_us, cam.gain_db = 10000.0, 0.0
        frame = cam.acquire(1)[0]
        with pytest.raises(ConfigError, match=r"gain_db.*GainRaw.*allowed \[0, 20.8"):
            cam.gain_db = 21.0
        with pytest.raises(ConfigError, match="black_level.*not supported"):
            cam.black_level = 4.0
    np.testing.assert_array_equal(frame.image, fake_ramp(frame.frame_id, 64, 8, 10000.0, 0, top=65535))


def test_grab_fake_1_by_id(capsys):
    doc = run_json(
        capsys,
        ["grab", "--backend", "aravis", "--device", "Fake_1", "--frames", "2", "--pixel-format", "Mono8", "--json"],
    )
    assert doc["device"]["profile"] == "aravis-fake" and doc["device"]["sensor_width"] == 2048
    for row in doc["frames"]:
        truth = fake_ramp(row["frame_id"], row["width"], row["height"], 10000.0, 0)
        assert (row["width"], row["height"]) == (512, 512)
        assert row["mean"] == pytest.approx(float(truth.mean()), abs=1e-9) and row["max"] == int(truth.max())


def test_grab_harvesters_test_producer_without_a_path(capsys, monkeypatch):
    monkeypatch.delenv("GENICAM_GENTL64_PATH", raising=False)
    doc = run_json(
        capsys,
        [
            "grab",
            "--backend",
            "harvesters",
            "--fake",
            "--device",
            "VikyTL_DEV_green",
            "--pixel-format",
            "Mono8",
            "--json",
        ],
    )
    assert doc["device"]["model"] == "Viky" and doc["frames"][0]["max"] == 255


def test_sweep_on_fake_1_through_the_hardware_rig(tmp_path, capsys):
    exposures = [2000.0, 10000.0, 20000.0]
    plan = load_plan(
        write_plan(
            tmp_path / "fake.toml",
            "fake",
            [
                {
                    "id": "fake",
                    "kind": "exposure",
                    "values": exposures,
                    "frames_per_point": 2,
                    "dark": "none",
                    "sensor": "imx250m",
                }
            ],
            camera={"backend": "aravis", "id": "Fake_1", "pixel_format": "Mono8", "window": [0, 0, 64, 32]},
        )
    )
    with (
        Dataset.create(tmp_path / "ds", plan.raw, plan_sha256=plan.sha256, sim=False) as data,
        HardwareRig(plan, None) as rig,
    ):
        SweepRunner(plan, data, rig).run()
    rows = Dataset.open(tmp_path / "ds").points().sort_values("point_index")
    assert rows["camera_model"].tolist() == ["Fake"] * 3 and rows["exposure_us_readback"].tolist() == exposures
    for exposure, (_, row) in zip(exposures, rows.iterrows(), strict=True):
        frames = [fake_ramp(int(f), 64, 32, exposure, 0) for f in row["frame_ids"]]
        assert row["mean_dn"] == pytest.approx(float(np.mean(frames)), abs=1e-9)
        saturated = float(np.mean(np.any(np.stack(frames) >= row["clip_level_dn"], axis=0)))
        assert row["saturated_fraction"] == pytest.approx(saturated) and bool(row["saturated"]) == (saturated > 0.002)
    # no light and no dark frames: EMVA 1288 refuses in one line
    assert main(["emva", "characterize", str(tmp_path / "ds"), "--out", str(tmp_path / "emva")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no dark frames" in err


def test_grab_fake_without_a_backend_grabs_fake_1_not_the_simulated_camera(capsys):
    doc = run_json(capsys, ["grab", "--fake", "--pixel-format", "Mono8", "--json"])
    assert (doc["device"]["backend"], doc["device"]["device_id"]) == ("aravis", "Fake_1")
    row = doc["frames"][0]
    assert row["mean"] == pytest.approx(float(fake_ramp(row["frame_id"], 512, 512, 10000.0, 0).mean()), abs=1e-9)


@pytest.mark.parametrize("layout,own_format", [("RG", "BayerBG8"), ("BG", "BayerRG8"), ("GB", "BayerGB8")])
def test_a_bayer_layout_is_grabbed_in_the_fake_cameras_own_format(capsys, layout, own_format):
    """Fake_1 starts in Mono8; asked for a layout, it is switched to the format that delivers it on this device (its
    profile records that its BayerRG8 and BayerBG8 carry each other's mosaic), with statistics per channel."""
    doc = run_json(capsys, ["grab", "--fake", "--bayer", layout, "--json"])
    row = doc["frames"][0]
    assert row["pixel_format"] == own_format and set(row["channels"]) == {"R", "G", "B"}
    with open_camera("aravis", fake=True, policy=FAST) as cam:
        assert cam.profile.bayer_layout(own_format) == layout


def test_an_explicit_pixel_format_is_kept_and_a_layout_it_lacks_refused(capsys):
    assert main(["grab", "--fake", "--bayer", "RG", "--pixel-format", "Mono8"]) == 2
    assert "bayer = 'RG': the device's PixelFormat Mono8 is monochrome" in capsys.readouterr().err
