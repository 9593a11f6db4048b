"""Camera outages for real: the GigE Vision camera server killed and restarted on its address, or frozen
(SIGSTOP/SIGCONT), while Aravis drives it over loopback. The server restarts at its power-on registers, so
a camera that only reconnected (without restoring its settings) would deliver frames of the wrong exposure."""

from __future__ import annotations

import subprocess
import threading
import time

import numpy as np
import pytest

from uwlab.drivers.camera import Policy, open_camera
from uwlab.drivers.camera.aravis_backend import GVCP_CCP_REGISTER, N_BUFFERS, AravisTransport
from uwlab.sim.devices.camera import SensorConfig, sensor_from_rig
from uwlab.errors import DeviceError
from tests.support.gige_server import Server

OUTAGE_S = 10.0
POLICY = Policy(timeout_s=2.0, reconnect_delay_s=0.2, reconnect_max_delay_s=2.0, outage_limit_s=30.0)
ROI = (600, 500, 128, 64)
EXPOSURE_US, GAIN_DB = 300.0, 6.0
# A set frame rate, as a lab sets one, restored with the rest. Free-running, the simulated camera streams this ROI
# at 300–600 frames/s; with the machine's cores starved (CI), bursts of frames then lost packets beyond their resend
# and one CI run met 21 incomplete frames in a row, the discard limit, right after the restart.
FRAME_RATE_HZ = 50.0


@pytest.fixture(scope="module")
def truth_mean_dn():
    mean_dn, _, _ = sensor_from_rig(None, seed=0).expected_dn(SensorConfig(EXPOSURE_US, GAIN_DB, 0.0, "Mono12p", *ROI))
    return float(mean_dn.mean())


def configure(cam) -> None:
    cam.pixel_format = "Mono12p"
    cam.set_roi(*ROI)
    cam.exposure_us, cam.gain_db = EXPOSURE_US, GAIN_DB
    cam.frame_rate_hz = FRAME_RATE_HZ


def register(address: str, name: str) -> str:
    """A register read by another program (arv-tool), as the restarted device holds it."""
    out = subprocess.run(["arv-tool-0.8", "-a", address, "control", name], capture_output=True, text=True, timeout=60)
    return out.stdout.split(" min:")[0].strip()


class FreezeAtStreamCreation:
    """Freeze ``server`` as Aravis is asked to create the stream (after the settings and the payload size were
    read) and thaw it ``outage_s`` later (never when None): a camera that goes silent while the stream is set up."""

    def __init__(self, server: Server, outage_s: float | None):
        self.server, self.outage_s = server, outage_s
        self.thaw: threading.Timer | None = None
        self.frozen = False

    def install(self, monkeypatch) -> None:
        start, hook = AravisTransport.start, self

        def start_with_freeze(transport) -> None:
            if not hook.frozen:
                transport._camera = _CreateStreamHook(transport._camera, hook.freeze)
            start(transport)

        monkeypatch.setattr(AravisTransport, "start", start_with_freeze)

    def freeze(self) -> None:
        if self.frozen:
            return
        self.frozen = True
        self.server.freeze()
        if self.outage_s is not None:
            self.thaw = threading.Timer(self.outage_s, self.server.thaw)
            self.thaw.start()

    def join(self) -> None:
        if self.thaw is not None:
            self.thaw.join()


class _CreateStreamHook:
    def __init__(self, camera, before) -> None:
        self._camera, self._before = camera, before

    def __getattr__(self, name: str):
        return getattr(self._camera, name)

    def create_stream(self, *args):
        self._before()
        return self._camera.create_stream(*args)


def check_frames(cam, frames, truth_mean_dn) -> None:
    assert len(frames) >= 3 and all(f.settings.exposure_us == EXPOSURE_US for f in frames)
    assert np.mean([f.image.mean() for f in frames]) == pytest.approx(truth_mean_dn, rel=0.02)
    settings = cam.read_settings()
    assert (settings.exposure_us, settings.gain_db, settings.pixel_format) == (EXPOSURE_US, GAIN_DB, "Mono12p")
    assert settings.frame_rate_hz == pytest.approx(FRAME_RATE_HZ)
    assert (settings.offset_x, settings.offset_y, settings.width, settings.height) == ROI


def test_a_10_s_server_restart_mid_stream_is_ridden_out_with_settings_restored(truth_mean_dn):
    servers = [Server()]
    try:
        with open_camera("aravis", servers[0].address, policy=POLICY) as cam:
            configure(cam)
            assert len(cam.acquire(2)) == 2
            cam.start()
            servers[0].kill()
            restart = threading.Timer(OUTAGE_S, lambda: servers.append(servers[0].restarted()))
            restart.start()
            started = time.monotonic()
            # more frames than the stream's buffers can have received between the start and the kill (on a loaded
            # machine, all of them): the acquisition must meet the outage, and it then starts over on the new
            # connection, so every frame comes from the restarted server
            frames = cam.acquire(N_BUFFERS + 3)
            assert time.monotonic() - started >= OUTAGE_S and cam.stats.reconnects == 1
            check_frames(cam, frames, truth_mean_dn)
            assert register(servers[-1].address, "ExposureTime") == f"ExposureTime = {EXPOSURE_US:g}"
            restart.join()
    finally:
        for server in servers:
            server.stop()


def test_a_restart_noticed_at_a_register_write_is_ridden_out(truth_mean_dn):
    servers = [Server()]
    try:
        with open_camera("aravis", servers[0].address, policy=POLICY) as cam:
            configure(cam)
            servers[0].kill()
            servers.append(servers[0].restarted())
            cam.gain_db = GAIN_DB
            assert cam.stats.reconnects == 1
            check_frames(cam, cam.acquire(3), truth_mean_dn)
    finally:
        for server in servers:
            server.stop()


def test_a_10_s_freeze_is_ridden_out_at_acquisition_start(truth_mean_dn):
    """The first command to meet the freeze times out and the camera reconnects; or, as one CI run on a loaded
    machine saw (0 reconnects, the right frames after 10.5 s), no command times out and the device, which kept its
    settings and its controller, answers late. Why no command timed out there is not established (a command
    waiting for Aravis's control channel behind its heartbeat thread's retries, for up to 5 s, would do it). Both
    ride the freeze out; the reconnect itself is held by the stream-creation and register-read tests."""
    server = Server()
    try:
        with open_camera("aravis", server.address, policy=POLICY) as cam:
            configure(cam)
            server.freeze()
            thaw = threading.Timer(OUTAGE_S, server.thaw)
            thaw.start()
            started = time.monotonic()
            frames = cam.acquire(3)
            assert time.monotonic() - started >= OUTAGE_S and cam.stats.reconnects <= 1
            check_frames(cam, frames, truth_mean_dn)
            thaw.join()
    finally:
        server.stop()


def test_a_10_s_freeze_as_the_stream_is_created_is_ridden_out(truth_mean_dn, monkeypatch):
    """Frozen as the stream is created, Aravis fails the creation with a plain error ("No stream channel
    found": it reads the channel count with the error ignored); the camera must tell that this device stopped
    answering, reconnect and restore its settings (two CI failures before it did)."""
    server = Server()
    freeze = FreezeAtStreamCreation(server, OUTAGE_S)
    try:
        with open_camera("aravis", server.address, policy=POLICY) as cam:
            configure(cam)
            freeze.install(monkeypatch)
            started = time.monotonic()
            frames = cam.acquire(3)
            assert time.monotonic() - started >= OUTAGE_S and cam.stats.reconnects == 1
            check_frames(cam, frames, truth_mean_dn)
    finally:
        freeze.join()
        server.stop()


def test_a_short_freeze_at_a_register_read_is_ridden_out(truth_mean_dn):
    """Frozen for 6 s: longer than two register reads' timeouts (2 × 2.5 s), so that our read always fails. Aravis's
    heartbeat thread reads the device every second over the same control channel, one read at a time: a heartbeat
    that begins at the freeze holds the channel for its 2.5 s before our read starts (Aravis 0.8.26,
    src/arvgvdevice.c), and a 4 s freeze then ended during our read, which was answered: no reconnect (one CI run
    in many). The test makes that worst case every time: a read like the heartbeat's holds the channel at the
    freeze (with it, a 4 s freeze gives no reconnect). Short enough that the old connection's heartbeats resume
    after the thaw and the device still counts it as its controller (measured: freezes of 4 s and 6 s locked a
    reconnecting camera out for good before it gave that control up explicitly; 8 s did not)."""
    server = Server()
    try:
        with open_camera("aravis", server.address, policy=POLICY) as cam:
            configure(cam)
            server.freeze()
            thaw = threading.Timer(6.0, server.thaw)
            thaw.start()
            heartbeat = threading.Thread(target=read_privilege, args=(cam.transport,))
            heartbeat.start()
            time.sleep(0.05)  # its read has the channel
            assert cam.verify_settings().exposure_us == EXPOSURE_US
            assert cam.stats.reconnects == 1
            check_frames(cam, cam.acquire(3), truth_mean_dn)
            thaw.join()
            heartbeat.join()
    finally:
        server.stop()


def read_privilege(transport: AravisTransport) -> None:
    """One read of the control channel privilege register, as Aravis's heartbeat thread makes every second (it
    fails while the device is frozen)."""
    from gi.repository import GLib

    try:
        transport._device.read_register(GVCP_CCP_REGISTER)
    except GLib.Error:
        pass


@pytest.mark.parametrize("when", ["before acquiring", "as the stream is created"])
def test_an_outage_past_the_limit_is_one_clear_error(monkeypatch, when):
    server = Server()
    freeze = FreezeAtStreamCreation(server, None)
    try:
        with open_camera("aravis", server.address, policy=Policy(timeout_s=1.0, outage_limit_s=4.0)) as cam:
            configure(cam)
            if when == "before acquiring":
                server.freeze()
            else:
                freeze.install(monkeypatch)
            started = time.monotonic()
            with pytest.raises(DeviceError) as info:
                cam.acquire(1)
            elapsed = time.monotonic() - started
        message = str(info.value)
        assert "device lost" in message and "limits: 12 attempts, 4 s" in message and "\n" not in message
        # it gives up on the 4 s limit: a little later on a loaded machine (each attempt's own timeouts), never
        # anywhere near the test's 180 s
        assert 4.0 <= elapsed < 60.0
    finally:
        freeze.join()
        server.stop()
