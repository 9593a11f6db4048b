"""harvesters backend, for real, against the GenTL producer ``viky.cti`` shipped in the genicam wheel."""
from __future__ import annotations

from pathlib import Path

import genicam
import numpy as np
import pytest

from uwlab.drivers.camera import BackendUnavailable, Policy, discover, open_camera
from uwlab.drivers.camera.harvesters_backend import cti_files
from uwlab.errors import ConfigError, DeviceError

VIKY = str(Path(genicam.__file__).parent / "viky.cti")


def test_viky_producer_is_shipped():
    assert Path(VIKY).is_file()


def test_discovery_lists_the_viky_devices():
    found, unavailable = discover(("harvesters",), cti=[VIKY])
    assert "harvesters" not in unavailable
    assert [d.id for d in found] == ["VikyTL_DEV_red", "VikyTL_DEV_green", "VikyTL_DEV_blue"]
    assert {d.vendor for d in found} == {"Machine Vision Games Ltd."} and {d.model for d in found} == {"Viky"}


def test_producer_lookup_from_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("GENICAM_GENTL64_PATH", f"{tmp_path}:{Path(VIKY).parent}")
    assert cti_files() == [Path(VIKY)]
    monkeypatch.setenv("GENICAM_GENTL64_PATH", str(tmp_path))
    with pytest.raises(BackendUnavailable, match="GENICAM_GENTL64_PATH"):
        cti_files()
    with pytest.raises(ConfigError, match="cti"):
        cti_files([str(tmp_path / "missing.cti")])


def test_node_map_access_acquisition_and_conversion():
    with open_camera("harvesters", "VikyTL_DEV_green", cti=[VIKY], policy=Policy(timeout_s=5.0)) as cam:
        assert cam.profile.name == "viky" and cam.info.serial == "1"
        assert cam.exposure_us is None and cam.gain_db is None
        cam.pixel_format = "Mono8"
        cam.set_roi(0, 0, 160, 120)
        cam.frame_rate_hz = 100.0
        with pytest.raises(ConfigError, match=r"AcquisitionFrameRate.*\[1, 200\]"):
            cam.frame_rate_hz = 500.0
        with pytest.raises(ConfigError, match="exposure_us.*not supported"):
            cam.exposure_us = 100.0
        frames = cam.acquire(3)
        assert all(f.image.shape == (120, 160) and f.image.dtype == np.uint8 for f in frames)
        assert frames[0].settings.frame_rate_hz == 100.0 and frames[0].settings.width == 160
        ids = [f.frame_id for f in frames]
        assert ids == sorted(ids) and len(set(ids)) == 3
        # Viky draws a binary (0/255) moving pattern: a mis-decoded buffer would show other codes
        assert all(set(np.unique(f.image).tolist()) == {0, 255} for f in frames)
        assert not np.array_equal(frames[0].image, frames[-1].image)


def test_timeout_and_unknown_device():
    with open_camera("harvesters", None, cti=[VIKY], policy=Policy(timeout_s=0.001)) as cam:
        cam.pixel_format = "Mono8"
        cam.frame_rate_hz = 1.0
        with pytest.raises(DeviceError, match="acquisition timeout"):
            cam.acquire(3)
    with pytest.raises(DeviceError, match="unknown device id 'nope'.*VikyTL_DEV_red"):
        open_camera("harvesters", "nope", cti=[VIKY])


def test_unsupported_pixel_format_is_reported():
    with open_camera("harvesters", "VikyTL_DEV_blue", cti=[VIKY]) as cam:
        cam.set_roi(0, 0, 100, 100)
        assert cam.pixel_format == "RGBa8"
        with pytest.raises(ConfigError, match="pixel_format.*RGBa8.*unsupported"):
            cam.acquire(1)
