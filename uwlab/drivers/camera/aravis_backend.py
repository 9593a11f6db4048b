"""Aravis backend: GigE Vision and USB3 Vision cameras through libaravis 0.8 (PyGObject).

Features are accessed by name through the device's GenICam node map (typed by node class:
enumeration, boolean, float, integer, string, command). Buffers come from an `Aravis.Stream`
with a small pool; a buffer whose status is not SUCCESS (missing packets, size mismatch, ...)
is reported as incomplete. ``device_id`` is an Aravis id (``vendor-model-serial``) or a GigE
Vision device's IP address (no discovery needed, e.g. on the loopback interface).

Lost devices (`DeviceLost`, which `Camera` answers by reconnecting): an Aravis device error
``timeout``, ``not-connected``, ``not-controller`` or ``protocol-error-access-denied`` on any
feature access or acquisition start — a device that stopped answering, or one that restarted and
no longer recognises us as its controller (GigE Vision control channel privilege). When no
buffer arrives in time, one register read and the controller status tell a silent or restarted
device from a plain timeout, as it does when an acquisition start fails with any other error
(`AravisTransport.start`). The register cache is disabled, so every read is a device read-back.

Aravis's fake camera (``Fake_1``, ``src/arvfakeinterface.c``; a GenICam device in process whose image is a diagonal
ramp scaled by its exposure and gain, ``src/arvfakecamera.c``) lives behind the ``Fake`` interface, which Aravis
leaves disabled by default: it is enabled to open ``Fake_1`` by id and for discovery with ``fake=True``
(``uwlab devices --fake``), and disabled otherwise, so that "the first camera found" is never the fake one.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from uwlab.drivers.camera.interface import DeviceEntry, DeviceLost, FrameTimeout, RawFrame, unknown_device
from uwlab.drivers.camera.pixels import pixel_format
from uwlab.errors import ConfigError, DeviceError

try:
    import gi

    gi.require_version("Aravis", "0.8")
    from gi.repository import Aravis, GLib
except (ImportError, ValueError) as exc:  # the caller reports the backend as unavailable
    raise ImportError(f"Aravis 0.8 GObject bindings not importable: {exc}") from exc

FAKE_INTERFACE = "Fake"
FAKE_DEVICE_IDS = ("Fake_1",)  # arvfakeinterface.c: ARV_FAKE_DEVICE_ID
N_BUFFERS = 8
GVCP_CCP_REGISTER = 0x0A00  # GigE Vision 2.0 bootstrap: control channel privilege (bits 0-1: exclusive, control)
SLOW_ANSWER_S = 0.5
LOST_CODES = frozenset(
    {
        Aravis.DeviceError.NOT_CONNECTED,
        Aravis.DeviceError.TIMEOUT,
        Aravis.DeviceError.NOT_FOUND,
        Aravis.DeviceError.NOT_CONTROLLER,
        Aravis.DeviceError.PROTOCOL_ERROR_ACCESS_DENIED,
    }
)
REJECTED_CODES = frozenset({Aravis.DeviceError.INVALID_PARAMETER, Aravis.DeviceError.PROTOCOL_ERROR_INVALID_PARAMETER})


def _is_device_error(exc: GLib.Error, codes: frozenset) -> bool:
    return exc.domain == GLib.quark_to_string(Aravis.device_error_quark()) and exc.code in {int(c) for c in codes}


def _fake_interface(enabled: bool) -> None:
    """Enable or disable Aravis's ``Fake`` interface (process-wide; Aravis's default: disabled)."""
    (Aravis.enable_interface if enabled else Aravis.disable_interface)(FAKE_INTERFACE)


def discover(fake: bool = False, **_: Any) -> list[DeviceEntry]:
    """Cameras on every Aravis interface; Aravis's fake camera too with ``fake``."""
    _fake_interface(fake)
    Aravis.update_device_list()
    return [
        DeviceEntry(
            "aravis",
            Aravis.get_device_id(i),
            Aravis.get_device_vendor(i) or "",
            Aravis.get_device_model(i) or "",
            Aravis.get_device_serial_nbr(i) or "",
        )
        for i in range(Aravis.get_n_devices())
    ]


def open_transport(device_id: str | None = None, fake: bool = False, **_: Any) -> AravisTransport:
    """Open ``device_id`` (the first camera found when None; Aravis's fake camera when None and ``fake``)."""
    return AravisTransport(device_id or (FAKE_DEVICE_IDS[0] if fake else None))


def _connect(device_id: str | None) -> Any:
    """An `Aravis.Camera` whose feature reads always go to the device (no register cache); the fake camera's
    interface is enabled only to open it by id."""
    _fake_interface(device_id in FAKE_DEVICE_IDS)
    camera = Aravis.Camera.new(device_id)
    camera.get_device().set_register_cache_policy(Aravis.RegisterCachePolicy.DISABLE)
    return camera


def _open_camera(device_id: str | None) -> Any:
    try:
        return _connect(device_id)
    except GLib.Error as exc:
        found = [d.id for d in discover(fake=True)]
        if device_id is None:
            raise DeviceError(f"aravis: no camera found ({exc.message})") from exc
        raise unknown_device("aravis", device_id, found) from exc


def _release(connection: list) -> None:
    """Let go of a lost connection ``[stream, camera, device]``: give up the GigE Vision control channel
    explicitly (the device may answer again, e.g. after a freeze, and a forgotten controller would keep it
    from us through its heartbeats), then drop the objects (Aravis finalises them)."""
    device = connection[2]
    if isinstance(device, Aravis.GvDevice) and device.is_controller():
        try:
            device.leave_control()
        except GLib.Error:
            pass
    connection.clear()


class AravisTransport:
    """`Transport` over one `Aravis.Camera`."""

    backend = "aravis"

    def __init__(self, device_id: str | None):
        self._camera = _open_camera(device_id)
        self.device_id = device_id or self._camera.get_device_id()
        self._device = self._camera.get_device()
        self._stream = None

    def _node(self, name: str) -> Any:
        return self._device.get_feature(name)

    def has(self, name: str) -> bool:
        node = self._node(name)
        try:
            return node is not None and bool(node.is_available())
        except GLib.Error as exc:
            if _is_device_error(exc, LOST_CODES):
                raise self._error(f"cannot evaluate {name}", exc) from exc
            return False

    def get(self, name: str) -> Any:
        node, dev = self._node(name), self._device
        try:
            if isinstance(node, Aravis.GcEnumeration) or isinstance(node, Aravis.GcString):
                return dev.get_string_feature_value(name)
            if isinstance(node, Aravis.GcBoolean):
                return bool(dev.get_boolean_feature_value(name))
            if isinstance(node, Aravis.GcFloat):
                return float(dev.get_float_feature_value(name))
            return int(dev.get_integer_feature_value(name))
        except GLib.Error as exc:
            raise self._error(f"cannot read {name}", exc) from exc

    def set(self, name: str, value: Any) -> None:
        node, dev = self._node(name), self._device
        try:
            if isinstance(node, Aravis.GcEnumeration) or isinstance(node, Aravis.GcString):
                dev.set_string_feature_value(name, str(value))
            elif isinstance(node, Aravis.GcBoolean):
                dev.set_boolean_feature_value(name, bool(value))
            elif isinstance(node, Aravis.GcFloat):
                dev.set_float_feature_value(name, float(value))
            else:
                dev.set_integer_feature_value(name, int(value))
        except GLib.Error as exc:
            if _is_device_error(exc, REJECTED_CODES) or "out of range" in exc.message.lower():
                raise ConfigError(name, value, f"rejected by the device ({exc.message})") from exc
            raise self._error(f"cannot write {name}={value!r}", exc) from exc

    def _error(self, what: str, exc: GLib.Error) -> DeviceError:
        if _is_device_error(exc, LOST_CODES):
            return DeviceLost(f"aravis: {self.device_id}: {what}: {exc.message}")
        return DeviceError(f"aravis: {self.device_id}: {what}: {exc.message}")

    def bounds(self, name: str) -> tuple[float, float] | None:
        node = self._node(name)
        try:
            if isinstance(node, Aravis.GcFloat):
                b = self._device.get_float_feature_bounds(name)
            elif isinstance(node, Aravis.GcInteger) and not isinstance(node, Aravis.GcEnumeration):
                b = self._device.get_integer_feature_bounds(name)
            else:
                return None
        except GLib.Error:
            return None
        return float(b.min), float(b.max)

    def entries(self, name: str) -> tuple[str, ...]:
        if not isinstance(self._node(name), Aravis.GcEnumeration):
            return ()
        try:
            return tuple(self._device.dup_available_enumeration_feature_values_as_strings(name))
        except GLib.Error as exc:
            raise self._error(f"cannot list {name}", exc) from exc

    def execute(self, name: str) -> None:
        try:
            self._device.execute_command(name)
        except GLib.Error as exc:
            raise self._error(f"cannot execute {name}", exc) from exc

    def start(self) -> None:
        """Create the stream and start acquiring. A device that went silent meanwhile is `DeviceLost`, whatever
        error Aravis gave: stream creation reads registers with their errors ignored (the stream channel count,
        the packet size: ``arv_gv_device_create_stream``, src/arvgvdevice.c; ``arv_gv_stream_new``,
        src/arvgvstream.c), so a silent camera fails it as "No stream channel found" or "Invalid packet size".
        Any error but a lost device's is therefore followed by one register read (`_check_alive`)."""
        try:
            payload = self._camera.get_payload()
            stream = self._stream = self._camera.create_stream(None, None)
            for _ in range(N_BUFFERS):
                stream.push_buffer(Aravis.Buffer.new_allocate(payload))
            self._camera.start_acquisition()
        except GLib.Error as exc:
            self._stream = None
            if not _is_device_error(exc, LOST_CODES):
                self._check_alive()
            raise self._error("cannot start acquisition", exc) from exc

    def stop(self) -> None:
        if self._stream is not None:
            try:
                self._camera.stop_acquisition()
            except GLib.Error:
                pass
            self._stream = None

    def fetch(self, timeout_s: float) -> RawFrame:
        """The next frame within `timeout_s`. A buffer Aravis hands back unfilled, status ``cleared``, is no frame
        and is not one: Aravis pushes one out when the packet that opens a block does not let it size a frame (an
        unknown payload or content type: ``_find_frame_data``, src/arvgvstream.c, 0.8.26), and it never began to
        fill it. It goes back to the stream and the wait goes on."""
        if self._stream is None:
            raise FrameTimeout(f"aravis: {self.device_id}: not acquiring")
        deadline = time.monotonic() + timeout_s
        while True:
            left_us = max(int((deadline - time.monotonic()) * 1e6), 1)
            buf = self._stream.timeout_pop_buffer(left_us)
            if buf is None:
                self._check_alive()
                raise FrameTimeout(f"aravis: {self.device_id}: no buffer within {timeout_s:g} s")
            if buf.get_status() != Aravis.BufferStatus.CLEARED:
                break
            self._stream.push_buffer(buf)
        try:
            return self._raw(buf)
        finally:
            self._stream.push_buffer(buf)

    def _raw(self, buf: Any) -> RawFrame:
        status = buf.get_status()
        if status != Aravis.BufferStatus.SUCCESS:  # its nick: missing-packets, size-mismatch, timeout, ...
            problem = f"Aravis buffer status {status.value_nick}"
            return RawFrame(int(buf.get_frame_id()), int(buf.get_timestamp()), 0, 0, "Mono8", b"", problem)
        fmt = pixel_format(int(buf.get_image_pixel_format()))
        return RawFrame(
            int(buf.get_frame_id()),
            int(buf.get_timestamp()),
            int(buf.get_image_width()),
            int(buf.get_image_height()),
            fmt.name,
            buf.get_data(),
        )

    def _check_alive(self) -> None:
        """After a frame timeout: `DeviceLost` if the device does not answer a register read at once (it was
        unreachable: unplugged, frozen, rebooting) or, on GigE Vision, no longer grants us control (it restarted,
        or dropped us after missed heartbeats; its CCP register is read, not Aravis's heartbeat view)."""
        started = time.monotonic()
        try:
            if isinstance(self._device, Aravis.GvDevice):
                privilege = self._device.read_register(GVCP_CCP_REGISTER)
            else:
                self._device.get_integer_feature_value("Width")
        except GLib.Error as exc:
            raise DeviceLost(f"aravis: {self.device_id}: device not responding ({exc.message})") from exc
        answered_s = time.monotonic() - started
        if answered_s > SLOW_ANSWER_S:
            raise DeviceLost(f"aravis: {self.device_id}: device answered after {answered_s:.1f} s (unreachable)")
        if isinstance(self._device, Aravis.GvDevice) and not (privilege & 0x3 and self._device.is_controller()):
            raise DeviceLost(f"aravis: {self.device_id}: control of the device lost (it restarted or was taken over)")

    def reconnect(self) -> None:
        """Open the device again. The old connection is released in a background thread (`_release`), as it
        may take seconds of timeouts with the lost device; until then the new one may not be the device's
        controller, which makes this attempt fail (`DeviceLost`) and the camera try again after its back-off."""
        old = [self._stream, self._camera, self._device]
        self._stream = self._camera = self._device = None
        threading.Thread(target=_release, args=(old,), name="aravis-release", daemon=True).start()
        del old
        try:
            camera = _connect(self.device_id)
        except GLib.Error as exc:
            raise DeviceLost(f"aravis: {self.device_id}: not back yet ({exc.message})") from exc
        device = camera.get_device()
        if isinstance(device, Aravis.GvDevice) and not device.is_controller():
            raise DeviceLost(f"aravis: {self.device_id}: back, but another controller still holds it")
        self._camera, self._device = camera, device

    def close(self) -> None:
        self.stop()
        self._camera = None
        self._device = None
