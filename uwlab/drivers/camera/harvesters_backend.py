"""harvesters backend: GenICam cameras through GenTL producers (``*.cti``).

Producers come from the ``cti`` option (paths to ``.cti`` files or folders) or from the
``GENICAM_GENTL64_PATH`` environment variable (folders separated by ``os.pathsep``), as the
GenTL standard (GenTL 1.5, section "Discovery") specifies. With ``fake=True`` the GenTL test
producers shipped in the installed ``genicam`` wheel are added (`bundled_producers`: ``viky.cti`` in
today's wheels, ``TLSimu.cti`` in older ones, where harvesters' own test suite looks for its
target), so ``uwlab devices --fake`` needs no path. Device information the remote node map lacks
(e.g. the Viky test producer has no ``DeviceVendorName``) comes from the GenTL device info. When
a producer does not time-stamp buffers, host time is used (``CLOCK_REALTIME``).

Buffers follow harvesters' non-blocking contract (``ImageAcquirer.try_fetch``): every call waits
at most the time left before our own deadline and returns a complete buffer or None. harvesters
re-queues an incomplete buffer itself, emits ``Events.INCOMPLETE_BUFFER`` and returns None; a
callback counts those events, so each one becomes an incomplete `RawFrame` that `Camera`
counts and discards. Every buffer we receive is queued back (``with buffer``). harvesters'
blocking ``fetch`` is not used: it silently re-queues incomplete buffers and restarts its timeout,
so a link delivering only incomplete frames would block it forever.

Pixels leave the buffer in at most one copy (`raw_frame`): the component data of a format harvesters delivers as it
is (Mono8, Mono16, ...) is a view into the GenTL buffer, which the producer refills once queued back, so it is
copied; the image harvesters decodes a packed format into (Mono10p, Mono12Packed, ...) is new memory, taken as it is.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from uwlab.drivers.camera.interface import DeviceEntry, DeviceLost, FrameTimeout, RawFrame, unknown_device
from uwlab.errors import ConfigError, DeviceError
from uwlab.model.data import MAX_BINARY_BYTES, check_input_file

try:
    import genicam
    from genicam import gentl
    from genicam import genapi
    from harvesters.core import Callback, Harvester, ImageAcquirer
except ImportError as exc:  # the caller reports the backend as unavailable
    raise ImportError(f"harvesters/genicam not importable: {exc}") from exc

ENV_VAR = "GENICAM_GENTL64_PATH"
POLL_S = 0.05
INCOMPLETE = "a GenTL buffer not complete"  # RawFrame.problem: GenTL says no more than that
LOST_ERRORS = (
    gentl.IoException,
    gentl.InvalidHandleException,
    gentl.NotInitializedException,
    gentl.ClosedException,
    genapi.TimeoutException,
)


def bundled_producers() -> list[Path]:
    """The GenTL test producers (``*.cti``) shipped inside the installed ``genicam`` package."""
    return sorted(Path(genicam.__file__).parent.glob("*.cti"))


def cti_files(cti: list[str] | tuple[str, ...] | None = None, fake: bool = False) -> list[Path]:
    """Producer files from explicit paths, else from ``GENICAM_GENTL64_PATH``; with ``fake``, the test producers
    (`bundled_producers`) too."""
    from uwlab.drivers.camera import BackendUnavailable

    roots = [Path(p) for p in cti] if cti else [Path(p) for p in os.environ.get(ENV_VAR, "").split(os.pathsep) if p]
    files: list[Path] = []
    for root in roots:
        if root.is_dir():
            files.extend(sorted(path for path in root.glob("*.cti") if path.is_file()))  # no FIFO or device
        elif cti:  # an explicit file: checked as every input is (a FIFO would block the library's open)
            files.append(check_input_file(root, "cti", MAX_BINARY_BYTES, "GenTL producer"))
        elif root.is_file():
            files.append(root)
    if fake:
        files.extend(path for path in bundled_producers() if path.resolve() not in {f.resolve() for f in files})
    if not files:
        raise BackendUnavailable(
            f"harvesters: no GenTL producer (*.cti) found; pass --cti or set {ENV_VAR} "
            f"(or --fake for the genicam package's test producer)"
        )
    return files


def _harvester(cti: list[str] | None, fake: bool = False) -> Harvester:
    h = Harvester()
    for path in cti_files(cti, fake):
        h.add_file(str(path))
    h.update()
    return h


def _info_str(info: Any, attr: str) -> str:
    try:
        return str(getattr(info, attr) or "")
    except gentl.GenericException:
        return ""


def discover(cti: list[str] | None = None, fake: bool = False, **_: Any) -> list[DeviceEntry]:
    h = _harvester(cti, fake)
    try:
        return [
            DeviceEntry(
                "harvesters",
                _info_str(d, "id_"),
                _info_str(d, "vendor"),
                _info_str(d, "model"),
                _info_str(d, "serial_number"),
            )
            for d in h.device_info_list
        ]
    finally:
        h.reset()


def open_transport(
    device_id: str | None = None, cti: list[str] | None = None, fake: bool = False, **_: Any
) -> HarvestersTransport:
    h = _harvester(cti, fake)
    ids = [_info_str(d, "id_") for d in h.device_info_list]
    if not ids or (device_id is not None and device_id not in ids):
        h.reset()
        raise unknown_device("harvesters", device_id or "<first>", ids)
    return HarvestersTransport(h, device_id or ids[0], cti, fake)


def owns_memory(array: np.ndarray) -> bool:
    """True when ``array`` lives in memory numpy allocated (e.g. the unpacked image harvesters decodes a packed
    format into), False for a view into foreign memory (a component's data over the GenTL buffer itself)."""
    while isinstance(array.base, np.ndarray):
        array = array.base
    return array.base is None


def raw_frame(buffer: Any) -> RawFrame:
    """A `RawFrame` of a harvesters `Buffer` that stays valid once the buffer is queued back: the component's data
    is copied only when it is a view into the GenTL buffer (a format harvesters delivers as is); an image harvesters
    has already unpacked into memory of its own (packed formats) is taken as it is, not copied again."""
    module = buffer.module
    component = buffer.payload.components[0]
    width, height = int(component.width), int(component.height)
    data = component.data
    if not owns_memory(data):  # a view into the GenTL buffer, which is queued back on return: the one copy
        data = data.copy()
    if data.size == width * height:  # one element per pixel: decoded (harvesters unpacks packed formats)
        data = data.reshape(height, width)
    try:
        ts = int(module.timestamp_ns)
    except gentl.GenericException:
        ts = time.time_ns()
    return RawFrame(
        int(module.frame_id),
        ts,
        width,
        height,
        str(component.data_format),
        data,
        "" if module.is_complete() else INCOMPLETE,
    )


class IncompleteBuffers(Callback):
    """Counts harvesters' ``INCOMPLETE_BUFFER`` events (buffers it discarded and re-queued)."""

    def __init__(self) -> None:
        self.count = 0

    def emit(self, context: object = None) -> None:
        self.count += 1


class HarvestersTransport:
    """`Transport` over one harvesters `ImageAcquirer`."""

    backend = "harvesters"

    def __init__(self, harvester: Harvester, device_id: str, cti: list[str] | None, fake: bool = False):
        self.device_id = device_id
        self._cti = cti
        self._fake = fake
        self._h = harvester
        self._open()

    def _open(self) -> None:
        try:
            self._ia = self._h.create({"id_": self.device_id})
        except gentl.GenericException as exc:
            raise DeviceError(f"harvesters: cannot open {self.device_id}: {exc}") from exc
        info = next(d for d in self._h.device_info_list if _info_str(d, "id_") == self.device_id)
        self._tl_info = {
            "DeviceVendorName": _info_str(info, "vendor"),
            "DeviceModelName": _info_str(info, "model"),
            "DeviceSerialNumber": _info_str(info, "serial_number"),
            "DeviceVersion": _info_str(info, "version"),
        }
        self._nm = self._ia.remote_device.node_map
        self.incomplete = IncompleteBuffers()
        self._ia.add_callback(ImageAcquirer.Events.INCOMPLETE_BUFFER, self.incomplete)

    def _node(self, name: str) -> Any:
        return self._nm.get_node(name)

    def has(self, name: str) -> bool:
        if name in self._tl_info:
            return True
        return self._nm.has_node(name) and genapi.is_available(self._node(name).node)

    def get(self, name: str) -> Any:
        if not self._nm.has_node(name) and name in self._tl_info:
            return self._tl_info[name]
        try:
            return self._node(name).value
        except LOST_ERRORS as exc:
            raise DeviceLost(f"harvesters: {self.device_id}: cannot read {name}: {exc}") from exc
        except genapi.GenericException as exc:
            raise DeviceError(f"harvesters: cannot read {name}: {exc}") from exc

    def set(self, name: str, value: Any) -> None:
        try:
            self._node(name).value = value
        except (genapi.OutOfRangeException, genapi.InvalidArgumentException) as exc:
            raise ConfigError(name, value, str(exc).split(":")[0]) from exc
        except LOST_ERRORS as exc:
            raise DeviceLost(f"harvesters: {self.device_id}: cannot write {name}={value!r}: {exc}") from exc
        except genapi.GenericException as exc:
            raise DeviceError(f"harvesters: cannot write {name}={value!r}: {exc}") from exc

    def bounds(self, name: str) -> tuple[float, float] | None:
        node = self._node(name)
        try:
            return float(node.min), float(node.max)
        except (AttributeError, genapi.GenericException):
            return None

    def entries(self, name: str) -> tuple[str, ...]:
        try:
            return tuple(e.symbolic for e in self._node(name).entries if genapi.is_available(e.node))
        except (AttributeError, genapi.GenericException):
            return ()

    def execute(self, name: str) -> None:
        self._node(name).execute()

    def start(self) -> None:
        self._ia.start()

    def stop(self) -> None:
        if self._ia.is_acquiring():
            self._ia.stop()

    def fetch(self, timeout_s: float) -> RawFrame:
        """The next buffer within ``timeout_s``: complete, or an incomplete one harvesters discarded."""
        deadline = time.monotonic() + timeout_s
        discarded = self.incomplete.count
        while (remaining := deadline - time.monotonic()) > 0:
            try:
                buffer = self._ia.try_fetch(timeout=min(remaining, POLL_S))
            except LOST_ERRORS as exc:
                raise DeviceLost(f"harvesters: {self.device_id}: {exc}") from exc
            if buffer is not None:
                with buffer:
                    return raw_frame(buffer)
            if self.incomplete.count > discarded:
                return RawFrame(-1, time.time_ns(), 0, 0, "Mono8", b"", INCOMPLETE)
        raise FrameTimeout(f"harvesters: no buffer within {timeout_s:g} s")

    def reconnect(self) -> None:
        self.close()
        self._h = _harvester(self._cti, self._fake)
        self._open()

    def close(self) -> None:
        try:
            self._ia.destroy()
        finally:
            self._h.reset()
