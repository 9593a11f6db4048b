"""harvesters backend, for real, against the GenTL producer ``viky.cti`` shipped in the genicam wheel."""

from __future__ import annotations

import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from genicam import gentl
from harvesters.util.pfnc import Dictionary

from uwlab.drivers.camera import BackendUnavailable, Policy, discover, open_camera
from uwlab.drivers.camera.harvesters_backend import bundled_producers, cti_files, owns_memory, raw_frame
from uwlab.drivers.camera.pixels import pack, pixel_format, unpack
from uwlab.errors import ConfigError, DeviceError

VIKY = str(bundled_producers()[0])  # the genicam wheel's viky.cti, found by the backend


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


# -- harvesters' buffer contract (try_fetch, requeue, our own deadline) ---------------------------------------
# viky always delivers complete buffers. To make the real producer's buffers incomplete, the one GenTL call
# that reports completeness, `genicam.gentl.Buffer.is_complete`, is replaced: harvesters' own try_fetch then
# discards and re-queues those buffers and emits INCOMPLETE_BUFFER, exactly as with a lossy link.


def viky_at(frame_rate_hz: float, policy: Policy):
    cam = open_camera("harvesters", "VikyTL_DEV_green", cti=[VIKY], policy=policy)
    cam.pixel_format = "Mono8"
    cam.set_roi(0, 0, 160, 120)
    cam.frame_rate_hz = frame_rate_hz
    return cam


def test_incomplete_buffers_are_discarded_counted_and_requeued(monkeypatch):
    handed: set[int] = set()  # the frames the producer handed over (under load it drops some: no buffer queued)

    def is_complete(buffer) -> bool:
        handed.add(buffer.frame_id)
        return buffer.frame_id % 3 != 0

    monkeypatch.setattr(gentl.Buffer, "is_complete", is_complete)
    with viky_at(200.0, Policy(timeout_s=5.0)) as cam:
        frames = cam.acquire(12)
        assert all(f.frame_id % 3 for f in frames) and len({f.frame_id for f in frames}) == 12
        assert cam.stats.discarded == len([i for i in handed if i % 3 == 0]) > 0
        assert cam.transport.incomplete.count == cam.stats.discarded
        assert len(cam.acquire(12)) == 12  # the buffers went back to the pool: the stream did not run dry


def test_a_link_delivering_only_incomplete_frames_fails_on_the_discard_limit(monkeypatch):
    monkeypatch.setattr(gentl.Buffer, "is_complete", lambda buffer: False)
    with viky_at(200.0, Policy(timeout_s=30.0, max_discarded_in_row=20)) as cam:
        started = time.monotonic()
        with pytest.raises(
            DeviceError, match=r"21 incomplete frames in a row \(the last: a GenTL buffer not complete\)"
        ):
            cam.acquire(1)
        assert cam.stats.discarded == 21 and cam.stats.delivered == 0 and time.monotonic() - started < 5.0


def test_a_link_delivering_only_incomplete_frames_times_out(monkeypatch):
    monkeypatch.setattr(gentl.Buffer, "is_complete", lambda buffer: False)
    with viky_at(100.0, Policy(timeout_s=1.0, max_discarded_in_row=10**6)) as cam:
        started = time.monotonic()
        with pytest.raises(DeviceError, match=r"acquisition timeout \(1000 ms, \d+ incomplete frames discarded\)"):
            cam.acquire(1)
        # the deadline is the whole acquisition's, not renewed by each incomplete frame (frames kept arriving);
        # the upper bound only catches a deadline that never comes, whatever the machine's load
        assert 1.0 <= time.monotonic() - started < 6.0 and cam.stats.discarded >= 10


def test_a_silent_stream_times_out_on_our_deadline():
    """The real producer, told to stop (AcquisitionStop on the device) while harvesters still streams."""
    with viky_at(100.0, Policy(timeout_s=0.5)) as cam:
        assert len(cam.acquire(2)) == 2
        cam.start()
        cam.transport.execute("AcquisitionStop")
        started = time.monotonic()
        with pytest.raises(DeviceError, match=r"acquisition timeout \(500 ms\)"):
            for _ in range(10):  # buffers filled before the stop are still delivered, then silence
                cam.acquire(1)
        assert time.monotonic() - started < 10 * 0.5 + 1.0


# -- the one copy: a frame never aliases a queued-back buffer, and is copied at most once ---------------------


def test_frames_kept_past_the_buffer_pool_are_not_overwritten():
    """viky queues 3 buffers: frames kept while 12 more arrive keep their own pixels (no view into a buffer)."""
    with viky_at(200.0, Policy(timeout_s=5.0)) as cam:
        kept = [(frame, frame.image.copy()) for frame in cam.frames(12)]
        assert all(np.array_equal(frame.image, snapshot) for frame, snapshot in kept)
        assert len({snapshot.tobytes() for _, snapshot in kept}) > 1  # the pattern moves: aliasing would show


def fake_buffer(data: np.ndarray, width: int, height: int, data_format: str) -> SimpleNamespace:
    module = SimpleNamespace(frame_id=7, timestamp_ns=1234, is_complete=lambda: True)
    component = SimpleNamespace(width=width, height=height, data=data, data_format=data_format)
    return SimpleNamespace(module=module, payload=SimpleNamespace(components=[component]))


def test_a_view_into_the_gentl_buffer_is_copied_once():
    gentl_memory = bytearray(range(12))  # what harvesters wraps with np.frombuffer for an unpacked format
    view = np.frombuffer(gentl_memory, np.uint8)
    assert not owns_memory(view) and not owns_memory(view[2:].reshape(2, 5))
    raw = raw_frame(fake_buffer(view, 4, 3, "Mono8"))
    gentl_memory[:] = bytes(12)  # the producer refills the buffer once it is queued back
    assert raw.data.shape == (3, 4) and raw.data.ravel().tolist() == list(range(12))
    assert (raw.frame_id, raw.timestamp_ns, raw.pixel_format, raw.complete) == (7, 1234, "Mono8", True)


def test_an_image_harvesters_has_unpacked_is_not_copied_again():
    """A packed format: harvesters' own decoder (the pfnc proxy its Component2DImage uses) yields a new array, taken
    as is — and decoded as uwlab decodes the same bytes."""
    image = np.arange(24, dtype=np.uint16).reshape(4, 6) * 170
    wire = pack(image, pixel_format("Mono12p")).tobytes()
    unpacked = Dictionary.get_proxy(symbolic="Mono12p").expand(np.frombuffer(wire, np.uint8))
    assert owns_memory(unpacked)
    raw = raw_frame(fake_buffer(unpacked, 6, 4, "Mono12p"))
    assert np.shares_memory(raw.data, unpacked) and raw.data.shape == (4, 6)
    assert np.array_equal(raw.data, unpack(wire, pixel_format("Mono12p"), 6, 4))
