"""The one camera interface driven through the sim backend: settings, read-back, triggers,
faults (injected), profiles."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest

from uwlab.drivers.camera import Camera, Policy, open_camera
from uwlab.drivers.camera.interface import Frame, FrameTimeout, RawFrame, Settings
from uwlab.drivers.camera.profiles import GENERIC_SFNC, select_profile
from uwlab.sim.devices.camera import SimFaults, SimNodeMap, SimSensor, SimTransport, SimTruth, flat_rate_map
from uwlab.errors import ConfigError, DeviceError

TRUTH = SimTruth("t", (64, 48), 12, 0.5, 64.0, 2.0, 7000.0, 10.0, 0.0, 0.0, 10.0, 1e6, 0.0, 24.0)
FAST = Policy(timeout_s=0.1, reconnect_delay_s=0.001)


def sim_camera(faults: SimFaults | None = None, rate: float = 1e5) -> Camera:
    sensor = SimSensor(TRUTH, flat_rate_map(rate), seed=0)
    return open_camera("sim", sensor=sensor, faults=faults, policy=FAST)


def test_info_profile_and_auto_modes_switched_off():
    with sim_camera() as cam:
        assert (cam.info.vendor, cam.info.model, cam.info.backend) == ("uwlab", "SimCam-t", "sim")
        assert (cam.info.sensor_width, cam.info.sensor_height) == (64, 48)
        assert cam.profile is GENERIC_SFNC
        assert cam.transport.get("ExposureAuto") == "Off" and cam.transport.get("GainAuto") == "Off"
        assert cam.temperature_c == TRUTH.temperature_c


def test_frames_carry_settings_read_back_from_the_device():
    with sim_camera() as cam:
        cam.exposure_us, cam.gain_db, cam.black_level, cam.pixel_format = 2000.0, 6.0, 16.0, "Mono12p"
        cam.set_roi(8, 4, 32, 16)
        frames = cam.acquire(3)
        assert [f.frame_id for f in frames] == [1, 2, 3]
        assert all(b.timestamp_ns > a.timestamp_ns for a, b in zip(frames, frames[1:], strict=False))
        for f in frames:
            assert f.image.shape == (16, 32) and f.image.dtype == np.uint16 and f.pixel_format == "Mono12p"
            s = f.settings
            assert (s.exposure_us, s.gain_db, s.black_level, s.width, s.height, s.offset_x, s.offset_y) == (
                2000.0,
                6.0,
                16.0,
                32,
                16,
                8,
                4,
            )
        k = TRUTH.system_gain(6.0)
        expected = k * (1e5 + TRUTH.dark_current_e_per_s) * 2e-3 + TRUTH.dark_offset_dn + 16.0
        assert np.mean([f.image.mean() for f in frames]) == pytest.approx(expected, rel=0.01)


def test_setter_reads_back_what_the_device_holds_not_what_was_asked():
    with sim_camera() as cam:
        cam.set_roi(0, 0, 32, 16)
        cam.transport.nodes.nodes["Gain"].value = 3.0
        cam.start()
        assert cam.acquire(1)[0].settings.gain_db == 3.0
        cam.stop()


def test_out_of_range_names_feature_and_allowed_range():
    with sim_camera() as cam:
        with pytest.raises(ConfigError, match=r"exposure_us.*ExposureTime.*allowed \[10, 1e\+06\]"):
            cam.exposure_us = 5.0
        with pytest.raises(ConfigError, match=r"gain_db.*Gain.*\[0, 24\]"):
            cam.gain_db = 30.0
        with pytest.raises(ConfigError, match=r"roi.width.*Width"):
            cam.set_roi(0, 0, 1000, 16)


def test_unsupported_pixel_format_and_unknown_device():
    with sim_camera() as cam:
        with pytest.raises(ConfigError, match="pixel_format.*RGB8"):
            cam.pixel_format = "RGB8"
    sensor = SimSensor(TRUTH, flat_rate_map(1.0))
    with pytest.raises(DeviceError, match="unknown device id 'cam7'.*found: sim0"):
        open_camera("sim", "cam7", sensor=sensor)
    with pytest.raises(ConfigError, match="backend"):
        open_camera("gopro")


def test_binning_and_mono8():
    with sim_camera() as cam:
        cam.set_binning(2, 2)
        cam.set_roi(0, 0, 32, 24)
        cam.pixel_format = "Mono8"
        frame = cam.acquire(1)[0]
        assert frame.image.shape == (24, 32) and frame.image.dtype == np.uint8
        assert frame.settings.binning == (2, 2)


def test_software_trigger_delivers_one_frame_per_trigger():
    with sim_camera() as cam:
        cam.set_trigger("software")
        frames = cam.acquire(4)
        assert [f.frame_id for f in frames] == [1, 2, 3, 4] and frames[0].settings.trigger == "software"
        cam.start()
        with pytest.raises(FrameTimeout):
            cam.transport.fetch(0.01)
        cam.set_trigger("free-run")
        assert cam.transport.fetch(0.01).frame_id == 5


def test_incomplete_frames_are_discarded_counted_and_reacquired():
    with sim_camera(SimFaults(incomplete_every=3)) as cam:
        frames = cam.acquire(10)
        assert len(frames) == 10 and all(f.frame_id % 3 for f in frames)
        assert cam.stats.discarded == 4 and cam.stats.delivered == 10


def test_only_incomplete_frames_fail_on_the_discard_limit_naming_the_last_ones_problem():
    sensor = SimSensor(TRUTH, flat_rate_map(1e5), seed=0)
    with open_camera("sim", sensor=sensor, faults=SimFaults(incomplete_every=1), policy=Policy(timeout_s=30.0)) as cam:
        with pytest.raises(DeviceError, match=r"^\S+: 21 incomplete frames in a row \(the last: half its payload "):
            cam.acquire(1)
        assert cam.stats.discarded == 21 and cam.stats.delivered == 0


def test_acquisition_timeout_is_a_device_error():
    with sim_camera(SimFaults(timeout_after=2)) as cam:
        with pytest.raises(DeviceError, match="acquisition timeout"):
            cam.acquire(5)


def test_device_lost_mid_stream_reconnects_and_restores_settings():
    with sim_camera(SimFaults(lost_after=3, failed_reconnects=1)) as cam:
        cam.exposure_us = 1234.0
        cam.set_roi(4, 4, 16, 8)
        frames = cam.acquire(6)
        assert cam.stats.reconnects == 1 and len(frames) == 6 and cam.stats.discarded == 0
        assert all(f.settings.exposure_us == 1234.0 and f.image.shape == (8, 16) for f in frames)
        assert cam.transport.get("ExposureAuto") == "Off"


def test_device_lost_for_good_raises_after_bounded_attempts():
    policy = Policy(timeout_s=0.1, reconnect_delay_s=0.001, reconnect_attempts=3)
    sensor = SimSensor(TRUTH, flat_rate_map(1e5), seed=0)
    with open_camera("sim", sensor=sensor, faults=SimFaults(lost_after=2, failed_reconnects=99), policy=policy) as cam:
        with pytest.raises(DeviceError, match="device lost .*not back after 3 reconnect attempts .*limits: 3 attempts"):
            cam.acquire(5)


def _session(cam: Camera) -> tuple[list[Frame], Settings]:
    """Every kind of camera operation: settings written and read, acquisition started, frames fetched."""
    cam.pixel_format = "Mono12p"
    cam.set_roi(8, 4, 32, 16)
    cam.exposure_us = 2000.0
    cam.gain_db = 6.0
    cam.black_level = 16.0
    assert cam.exposure_us == 2000.0 and cam.gain_db == 6.0
    cam.start()
    frames = cam.acquire(3)
    cam.stop()
    cam.exposure_us = 3000.0
    frames += cam.acquire(2)
    return frames, cam.read_settings()


def test_a_loss_at_any_operation_is_survived_with_the_settings_restored_and_verified():
    """The device vanishes (and comes back power-cycled, registers at their defaults) at the 1st, 2nd, ...
    device operation of a session: every session ends as the fault-free one does."""
    with sim_camera() as cam:
        opened = cam.transport.operations
        frames, reference = _session(cam)
        operations = cam.transport.operations
    expected_means = [f.image.mean() for f in frames]
    assert operations - opened > 40
    for at in range(opened + 1, operations + 1):
        with sim_camera(SimFaults(lost_at_operation=at, failed_reconnects=1)) as cam:
            frames, settings = _session(cam)
            assert cam.stats.reconnects == 1, at
            assert settings == reference, at
            assert [f.settings.exposure_us for f in frames] == [2000.0] * 3 + [3000.0] * 2, at
            np.testing.assert_allclose([f.image.mean() for f in frames], expected_means, rtol=0.01, err_msg=str(at))
            assert cam.transport.nodes.value("ExposureAuto") == "Off"


def test_an_outage_within_the_limit_is_ridden_out_and_one_past_it_is_one_error():
    policy = Policy(timeout_s=0.5, reconnect_delay_s=0.05, reconnect_max_delay_s=0.2, outage_limit_s=1.5)
    sensor = SimSensor(TRUTH, flat_rate_map(1e5), seed=0)
    with open_camera("sim", sensor=sensor, policy=policy) as cam:
        cam.exposure_us = 1500.0
        cam.transport.cut(outage_s=1.0)
        started = time.monotonic()
        assert len(cam.acquire(2)) == 2 and cam.stats.reconnects == 1
        assert 1.0 <= time.monotonic() - started < 1.5
        assert cam.read_settings().exposure_us == 1500.0
        cam.transport.cut(outage_s=60.0)
        started = time.monotonic()
        with pytest.raises(DeviceError, match=r"not back after \d+ reconnect attempts over 1\.\d s .*1\.5 s"):
            cam.gain_db = 3.0
        assert time.monotonic() - started < 2.5


class StuckExposureTransport(SimTransport):
    """A simulated camera that comes back from an outage ignoring exposure writes (a faulty device)."""

    def reconnect(self) -> None:
        super().reconnect()
        self.nodes.nodes["ExposureTime"].writable = False
        self.nodes.set = lambda name, value, nodes=self.nodes: (
            None if name == "ExposureTime" else SimNodeMap.set(nodes, name, value)
        )


class FlappingTransport(SimTransport):
    """A simulated camera that reconnects and takes its settings back, then is lost at the next frame (a flapping
    link): every reconnect succeeds, no frame ever arrives."""

    flap = False

    def reconnect(self) -> None:
        super().reconnect()
        self.flap = True

    def fetch(self, timeout_s: float) -> RawFrame:
        if self.flap:
            self.flap = False
            self.cut(outage_s=0.0)
        return super().fetch(timeout_s)


def test_a_device_lost_again_after_every_reconnect_is_one_error_within_the_limits():
    sensor = SimSensor(TRUTH, flat_rate_map(1e5), seed=0)
    policy = Policy(timeout_s=0.1, reconnect_delay_s=0.001, reconnect_attempts=4)
    with Camera(FlappingTransport(sensor), policy=policy) as cam:
        cam.transport.cut(outage_s=0.0)
        with pytest.raises(DeviceError, match="not back after 4 reconnect attempts"):
            cam.acquire(1)


def test_a_device_that_does_not_take_its_settings_back_is_one_clear_error():
    sensor = SimSensor(TRUTH, flat_rate_map(1e5), seed=0)
    with Camera(
        StuckExposureTransport(sensor), policy=Policy(timeout_s=0.1, reconnect_delay_s=0.001, reconnect_attempts=2)
    ) as cam:
        cam.exposure_us = 1234.0
        cam.transport.cut(outage_s=0.0)
        with pytest.raises(DeviceError, match="settings not restored after reconnecting: exposure_us: 1234.0 -> "):
            cam.acquire(1)


def test_context_manager_releases_device_on_exception():
    cam = sim_camera()
    with pytest.raises(RuntimeError):
        with cam:
            cam.start()
            raise RuntimeError("boom")
    assert cam.transport._closed and not cam.transport._streaming


class DictTransport:
    """A minimal transport with an arbitrary feature dictionary (vendor quirks)."""

    backend = "dict"
    device_id = "dict0"

    def __init__(self, features: dict[str, Any], bounds: dict[str, tuple[float, float]]):
        self.features, self._bounds, self.writes = dict(features), bounds, []

    def has(self, name):
        return name in self.features

    def get(self, name):
        return self.features[name]

    def set(self, name, value):
        self.writes.append((name, value))
        self.features[name] = value

    def bounds(self, name):
        return self._bounds.get(name)

    def entries(self, name):
        return ("Off", "Continuous") if name.endswith("Auto") else ()

    def execute(self, name):
        pass

    def start(self):
        pass

    def stop(self):
        pass

    def fetch(self, timeout_s):
        return RawFrame(1, 0, 2, 1, "Mono8", b"\x01\x02")

    def reconnect(self):
        pass

    def close(self):
        pass


@pytest.mark.parametrize(
    "vendor,model,profile",
    [
        ("FLIR", "Blackfly S BFS-U3-51S5M", "flir-blackfly-s"),
        ("Allied Vision Technologies", "GT1380", "allied-vision-gt"),
        ("Aravis", "Fake", "aravis-fake"),
        ("Machine Vision Games Ltd.", "Viky", "viky"),
        ("Acme", "X1", "generic-sfnc"),
    ],
)
def test_profile_selection(vendor, model, profile):
    assert select_profile(vendor, model).name == profile


def test_allied_vision_legacy_names_through_the_same_interface():
    t = DictTransport(
        {
            "DeviceVendorName": "Allied Vision Technologies",
            "DeviceModelName": "GT1380",
            "DeviceID": "02-2142A",
            "ExposureTimeAbs": 1000.0,
            "GainRaw": 0,
            "ExposureAuto": "Continuous",
            "GainAuto": "Continuous",
            "AcquisitionFrameRateAbs": 20.0,
            "PixelFormat": "Mono8",
            "Width": 2,
            "Height": 1,
        },
        {"ExposureTimeAbs": (25.0, 6e7), "GainRaw": (0, 26)},
    )
    cam = Camera(t)
    assert cam.profile.name == "allied-vision-gt" and cam.info.serial == "02-2142A"
    assert ("ExposureAuto", "Off") in t.writes and ("GainAuto", "Off") in t.writes
    cam.exposure_us, cam.gain_db = 5000.0, 12.0
    assert (
        t.features["ExposureTimeAbs"] == 5000.0
        and t.features["GainRaw"] == 12
        and isinstance(t.features["GainRaw"], int)
    )
    assert cam.frame_rate_hz == 20.0 and cam.black_level is None
    with pytest.raises(ConfigError, match="GainRaw.*allowed \\[0, 26\\]"):
        cam.gain_db = 30.0
    with pytest.raises(ConfigError, match="black_level.*not supported"):
        cam.black_level = 3.0
    assert cam.acquire(1)[0].image.tolist() == [[1, 2]]
