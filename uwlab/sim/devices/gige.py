"""GigE Vision server for the simulated camera: a minimal GVCP/GVSP device on a loopback address.

Why our own responder rather than Aravis's `ArvGvFakeCamera`: the fake camera's register map
and XML are fixed (``ExposureTimeAbs``, ``GainRaw``, Mono8/Mono16, 8-bit Bayer), its fill callback cannot
be set from Python safely, and its received size follows its own default pattern. Here every
register is backed by `SimNodeMap`, so exposure, gain, black level, ROI/binning and all Mono
pixel formats (packed ones included) reach the EMVA 1288 renderer (`SimSensor`), and faults can
be injected. Protocol: GigE Vision 2.0 — GVCP on UDP 3956 (DISCOVERY, READREG, WRITEREG,
READMEM, WRITEMEM, PACKETRESEND; control channel privilege with heartbeat timeout) and GVSP
with standard 16-bit block ids (leader / payload / trailer, image payload type 0x0001),
device time stamps in ns (tick frequency 1 GHz).

GVCP's port is fixed, so distinct servers use distinct loopback addresses (127.0.0.0/8).
Discovery broadcasts (Aravis sends them to 255.255.255.255 from every interface, ``lo``
included) reach a wildcard socket shared by all servers (``SO_REUSEADDR``); each server answers
from its own address, so ``arv-tool-0.8`` lists every running simulated camera. Because the
sockets share their port, binding cannot tell that an address is taken: each server claims its
address with an abstract Unix socket named after it (freed by the kernel when the process ends),
and a second server on the same address is refused, naming the process that holds it.
"""

from __future__ import annotations

import select
import socket
import struct
import threading
import time
import zlib
from dataclasses import dataclass

from uwlab.drivers.camera.pixels import pack, pixel_format
from uwlab.sim.devices.camera import SimNodeMap, SimSensor
from uwlab.sim.devices.gige_xml import (
    ENUM_VALUES,
    SCPS_ADDRESS,
    STRING_REGISTERS,
    XML_ADDRESS,
    XML_FILE,
    genicam_xml,
    register_map,
)
from uwlab.errors import ConfigError, DeviceError

GVCP_PORT = 3956
CMD_DISCOVERY, CMD_PACKETRESEND, CMD_READREG, CMD_WRITEREG, CMD_READMEM, CMD_WRITEMEM = (
    0x02,
    0x40,
    0x80,
    0x82,
    0x84,
    0x86,
)
STATUS_OK, STATUS_NOT_IMPLEMENTED, STATUS_INVALID_PARAMETER, STATUS_INVALID_ADDRESS, STATUS_WRITE_PROTECT = (
    0x0000,
    0x8001,
    0x8002,
    0x8003,
    0x8004,
)
STATUS_ACCESS_DENIED = 0x8006
REG_CCP, REG_HEARTBEAT, REG_SCP, REG_SCDA = 0x0A00, 0x0938, 0x0D00, 0x0D18
GVSP_LEADER, GVSP_TRAILER, GVSP_PAYLOAD, GVSP_H264 = 1, 2, 3, 5
GVSP_OVERHEAD = 20 + 8 + 8  # IP + UDP + GVSP headers, counted in the packet size (GigE Vision 2.0, 4.3)
RESEND_FRAMES = 4


@dataclass(frozen=True)
class GigeFaults:
    """Fault injection: every ``incomplete_every``-th frame loses one payload packet for good (resend requests for
    it are refused); before every ``stray_every``-th frame a stray packet, the opening of a block in a stream format
    this camera never sends (H.264, GVSP content type 5), which a host cannot make a frame of."""

    incomplete_every: int = 0
    stray_every: int = 0


def _gvsp_packet(block_id: int, content: int, packet_id: int, body: bytes) -> bytes:
    """A GVSP packet with the standard header: status OK, 16-bit block id, content type and 24-bit packet id."""
    return struct.pack(">HHI", 0, block_id, (content << 24) | packet_id) + body


def _mac(address: str) -> bytes:
    return b"\x02\x00" + socket.inet_aton(address)


class GigeCameraServer:
    """Serve a simulated camera on ``address`` (a loopback IPv4 address) until `close`."""

    def __init__(
        self, sensor: SimSensor, address: str = "127.0.0.1", serial: str | None = None, faults: GigeFaults | None = None
    ):
        self.sensor = sensor
        self.address = address
        self.faults = faults or GigeFaults()
        serial = serial or f"GV{zlib.crc32(address.encode()) % 100000:05d}"
        self.nodes = SimNodeMap(sensor.truth, serial=serial, exposure_us=sensor.auto_exposure_us())
        self.xml = genicam_xml(self.nodes)
        self.registers = register_map()
        self._lock = threading.Lock()
        self._bootstrap = self._make_bootstrap()
        self._ctrl = _Control()
        self._stream = _StreamState()
        self._stop = threading.Event()
        self._claim = self._claim_address(address)
        try:
            self._gvcp = self._bind(address)
        except BaseException:
            self._claim.close()
            raise
        self._discovery = self._bind_broadcast()
        self._gvsp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._gvsp.bind((address, 0))
        self._gvsp.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 8 << 20)
        self._threads = [
            threading.Thread(target=self._serve_control, daemon=True),
            threading.Thread(target=self._serve_stream, daemon=True),
        ]

    @property
    def device_id(self) -> str:
        """The id Aravis gives this device: ``vendor-model-serial``."""
        return "-".join(str(self.nodes.value(n)) for n in ("DeviceVendorName", "DeviceModelName", "DeviceSerialNumber"))

    @property
    def stream_port(self) -> int:
        """The UDP port GVSP packets are sent from."""
        return self._gvsp.getsockname()[1]

    @staticmethod
    def _claim_address(address: str) -> socket.socket:
        """Hold `address` for this process (see the module docstring); `ConfigError` if another server holds it."""
        name = f"\0uwlab-gige-sim-{address}"
        claim = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            claim.bind(name)
            claim.listen(1)
            return claim
        except OSError:
            claim.close()
        holder = "another process"
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
            try:
                probe.connect(name)
                pid, _, _ = struct.unpack("3i", probe.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, 12))
                holder = f"process {pid}"
            except OSError:
                pass
        raise ConfigError(
            "address", address, f"in use: a simulated camera of {holder} serves it; choose another 127.x.y.z address"
        )

    @staticmethod
    def _bind(address: str) -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((address, GVCP_PORT))
        except OSError as exc:
            sock.close()
            raise DeviceError(f"GigE sim: cannot bind {address}:{GVCP_PORT}: {exc}") from exc
        return sock

    @staticmethod
    def _bind_broadcast() -> socket.socket | None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(("", GVCP_PORT))
        except OSError:
            sock.close()
            return None
        return sock

    def start(self) -> GigeCameraServer:
        for t in self._threads:
            t.start()
        return self

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            if t.is_alive():
                t.join(timeout=5)
        for sock in (self._gvcp, self._discovery, self._gvsp, self._claim):
            if sock is not None:
                sock.close()

    def __enter__(self) -> GigeCameraServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- bootstrap and registers ------------------------------------------------------------
    def _make_bootstrap(self) -> bytearray:
        boot = bytearray(0x1000)
        words = {
            0x0000: 0x00020000,
            0x0004: 0x80000001,
            0x0010: 0x00000006,
            0x0014: 0x00000006,
            0x0024: struct.unpack(">I", socket.inet_aton(self.address))[0],
            0x0034: 0xFF000000,
            0x0600: 1,
            0x0900: 0,
            0x0904: 1,
            0x0934: 0x00000004 | 0x00000002,
            REG_HEARTBEAT: 3000,
            0x093C: 0,
            0x0940: 1_000_000_000,
            SCPS_ADDRESS: 8192,
            0x0D08: 0,
        }
        for addr, value in words.items():
            struct.pack_into(">I", boot, addr, value)
        boot[0x0008:0x0010] = b"\x00\x00" + _mac(self.address)
        for name, (addr, length) in STRING_REGISTERS.items():
            if self.nodes.has(name):
                boot[addr : addr + length] = str(self.nodes.value(name)).encode()[: length - 1].ljust(length, b"\0")
        url = f"Local:{XML_FILE};{XML_ADDRESS:X};{len(self.xml):X}".encode()
        boot[0x0200 : 0x0200 + len(url)] = url
        return boot

    def read_memory(self, address: int, size: int) -> bytes:
        if XML_ADDRESS <= address < XML_ADDRESS + len(self.xml) + 0x1000:
            start = address - XML_ADDRESS
            return self.xml[start : start + size].ljust(size, b"\0")
        reg = self.registers.get(address)
        if reg is not None and reg.kind == "float":
            return struct.pack(">d", float(self._feature_value(reg.feature)))[:size].ljust(size, b"\0")
        return b"".join(struct.pack(">I", self.read_register(address + i)) for i in range(0, size, 4))[:size]

    def read_register(self, address: int) -> int:
        if address < len(self._bootstrap):
            if address == REG_CCP:
                return self._ctrl.privilege
            return struct.unpack_from(">I", self._bootstrap, address & ~3)[0]
        reg = self.registers.get(address)
        if reg is None:
            raise KeyError(address)
        if reg.part != "value":
            bounds = self.nodes.bounds(reg.feature)
            if bounds is None:  # only features with bounds have min and max registers (`register_map`)
                raise KeyError(address)
            lo, hi = bounds
            return int(lo if reg.part == "min" else hi)
        value = self._feature_value(reg.feature)
        if reg.feature in ENUM_VALUES:
            return ENUM_VALUES[reg.feature][value]
        if reg.feature == "PayloadSize":
            return self.nodes.payload_size()
        return int(value or 0)

    def _feature_value(self, name: str):
        node = self.nodes.nodes[name]
        return None if node.kind == "cmd" else self.nodes.value(name)

    def write_register(self, address: int, value: int) -> None:
        if address < len(self._bootstrap):
            self._write_bootstrap(address, value)
            return
        reg = self.registers.get(address)
        if reg is None or reg.part != "value":
            raise KeyError(address)
        node = self.nodes.nodes[reg.feature]
        if node.kind == "cmd":
            self._command(reg.feature)
        elif reg.feature in ENUM_VALUES:
            names = {v: k for k, v in ENUM_VALUES[reg.feature].items()}
            if value not in names:
                raise ConfigError(reg.feature, value, "not an enumeration value")
            self._set(reg.feature, names[value])
        else:
            self._set(reg.feature, value)

    def write_float(self, address: int, data: bytes) -> None:
        reg = self.registers.get(address)
        if reg is None or reg.kind != "float" or len(data) != 8:
            raise KeyError(address)
        self._set(reg.feature, struct.unpack(">d", data)[0])

    def _set(self, name: str, value) -> None:
        if self._stream.running and name in (
            "Width",
            "Height",
            "OffsetX",
            "OffsetY",
            "PixelFormat",
            "BinningHorizontal",
            "BinningVertical",
        ):
            raise PermissionError(name)
        with self._lock:
            self.nodes.set(name, value)

    def _write_bootstrap(self, address: int, value: int) -> None:
        if address == REG_CCP:
            self._ctrl.privilege = value & 0x3
            if not self._ctrl.privilege:
                self._stream.running = False
            return
        if address not in (REG_HEARTBEAT, REG_SCP, REG_SCDA, SCPS_ADDRESS, 0x0D08, 0x0944):
            raise PermissionError(address)
        struct.pack_into(">I", self._bootstrap, address, value & 0xFFFFFFFF)

    def _command(self, name: str) -> None:
        if name == "AcquisitionStart":
            self._stream.start()
        elif name == "AcquisitionStop":
            self._stream.running = False
        elif name == "TriggerSoftware" and self._stream.running:
            self._stream.triggers += 1

    # -- GVCP ---------------------------------------------------------------------------------
    def _serve_control(self) -> None:
        socks = [s for s in (self._gvcp, self._discovery) if s is not None]
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select(socks, [], [], 0.05)
                for s in ready:
                    packet, peer = s.recvfrom(2048)
                    self._handle(packet, peer, from_broadcast=s is self._discovery)
            except OSError:
                return
            self._check_heartbeat()

    def _check_heartbeat(self) -> None:
        timeout_s = struct.unpack_from(">I", self._bootstrap, REG_HEARTBEAT)[0] / 1000.0
        if self._ctrl.privilege and time.monotonic() - self._ctrl.last_seen > timeout_s:
            self._ctrl.privilege = 0
            self._stream.running = False

    def _handle(self, packet: bytes, peer: tuple[str, int], from_broadcast: bool) -> None:
        if len(packet) < 8 or packet[0] != 0x42:
            return
        flags, command, length, req_id = packet[1], *struct.unpack_from(">HHH", packet, 2)
        payload = packet[8 : 8 + length]
        if from_broadcast and command != CMD_DISCOVERY:
            return
        if self._ctrl.privilege and peer == self._ctrl.peer:
            self._ctrl.last_seen = time.monotonic()
        status, answer = self._dispatch(command, payload, peer)
        if command == CMD_PACKETRESEND or not (flags & 0x01 or command == CMD_DISCOVERY):
            return
        header = struct.pack(">HHHH", status, command + 1, len(answer), req_id)
        self._gvcp.sendto(header + answer, peer)

    def _dispatch(self, command: int, payload: bytes, peer: tuple[str, int]) -> tuple[int, bytes]:
        try:
            if command == CMD_DISCOVERY:
                return STATUS_OK, bytes(self._bootstrap[:0xF8])
            if command == CMD_READREG:
                addrs = struct.unpack(f">{len(payload) // 4}I", payload)
                return STATUS_OK, b"".join(struct.pack(">I", self.read_register(a)) for a in addrs)
            if command == CMD_READMEM:
                address, size = struct.unpack(">IxxH", payload[:8])
                return STATUS_OK, struct.pack(">I", address) + self.read_memory(address, size)
            if command == CMD_PACKETRESEND:
                self._resend(payload)
                return STATUS_OK, b""
            if command in (CMD_WRITEREG, CMD_WRITEMEM) and not self._may_write(peer, payload, command):
                return STATUS_ACCESS_DENIED, b""
            if command == CMD_WRITEREG:
                pairs = struct.unpack(f">{len(payload) // 4}I", payload)
                for i in range(0, len(pairs), 2):
                    self.write_register(pairs[i], pairs[i + 1])
                return STATUS_OK, struct.pack(">HH", 0, len(pairs) // 2)
            if command == CMD_WRITEMEM:
                address = struct.unpack(">I", payload[:4])[0]
                self._write_memory(address, payload[4:])
                return STATUS_OK, struct.pack(">HH", 0, len(payload) - 4)
        except (KeyError, struct.error):
            return STATUS_INVALID_ADDRESS, b""
        except ConfigError:
            return STATUS_INVALID_PARAMETER, b""
        except PermissionError:
            return STATUS_WRITE_PROTECT, b""
        return STATUS_NOT_IMPLEMENTED, b""

    def _may_write(self, peer: tuple[str, int], payload: bytes, command: int) -> bool:
        if self._ctrl.privilege == 0:
            if command == CMD_WRITEREG and struct.unpack_from(">I", payload)[0] == REG_CCP:
                self._ctrl.peer, self._ctrl.last_seen = peer, time.monotonic()
                return True
            return False
        return peer == self._ctrl.peer

    def _write_memory(self, address: int, data: bytes) -> None:
        reg = self.registers.get(address)
        if reg is not None and reg.kind == "float":
            self.write_float(address, data)
            return
        for i in range(0, len(data) - 3, 4):
            self.write_register(address + i, struct.unpack_from(">I", data, i)[0])

    # -- GVSP ---------------------------------------------------------------------------------
    def _serve_stream(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            st = self._stream
            if not st.running:
                time.sleep(0.005)
                next_t = time.monotonic()
                continue
            if self.nodes.value("TriggerMode") == "On":
                if st.triggers == 0:
                    time.sleep(0.001)
                    continue
                st.triggers -= 1
            else:
                delay = next_t - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                next_t = max(next_t + self.nodes.frame_period_s(), time.monotonic())
            self._send_frame()

    def _send_frame(self) -> None:
        with self._lock:
            cfg = self.nodes.sensor_config()
            self.nodes.run_auto_modes()
        fmt = pixel_format(cfg.pixel_format)
        payload = pack(self.sensor.render(cfg), fmt).tobytes()
        st = self._stream
        st.block_id = st.block_id % 0xFFFF + 1
        packets = self._packets(st.block_id, fmt.code, cfg, payload)
        drop = bool(self.faults.incomplete_every) and st.block_id % self.faults.incomplete_every == 0
        lost = 1 if drop and len(packets) > 2 else None
        st.history[st.block_id] = (packets, lost)
        st.history.pop((st.block_id - RESEND_FRAMES - 1) % 0xFFFF + 1, None)
        target = self._stream_target()
        if target is not None and self.faults.stray_every and st.block_id % self.faults.stray_every == 0:
            self._send(_gvsp_packet(st.block_id, GVSP_H264, 0, bytes(16)), target)
        for i, pkt in enumerate(packets):
            if i != lost and target is not None:
                self._send(pkt, target)

    def _packets(self, block_id: int, code: int, cfg, payload: bytes) -> list[bytes]:
        size = (struct.unpack_from(">I", self._bootstrap, SCPS_ADDRESS)[0] & 0xFFFF) - GVSP_OVERHEAD
        chunk = max(size - size % 4, 64)
        ts = time.monotonic_ns()
        leader = struct.pack(
            ">HHIIIIIIIHH",
            0,
            0x0001,
            ts >> 32,
            ts & 0xFFFFFFFF,
            code,
            cfg.width,
            cfg.height,
            cfg.offset_x,
            cfg.offset_y,
            0,
            0,
        )
        bodies = [payload[i : i + chunk] for i in range(0, len(payload), chunk)]
        parts = [
            (GVSP_LEADER, leader),
            *((GVSP_PAYLOAD, b) for b in bodies),
            (GVSP_TRAILER, struct.pack(">HHI", 0, 0x0001, cfg.height)),
        ]
        return [_gvsp_packet(block_id, content, pid, body) for pid, (content, body) in enumerate(parts)]

    def _stream_target(self) -> tuple[str, int] | None:
        port = struct.unpack_from(">I", self._bootstrap, REG_SCP)[0] & 0xFFFF
        ip = socket.inet_ntoa(self._bootstrap[REG_SCDA : REG_SCDA + 4])
        return (ip, port) if port else None

    def _send(self, packet: bytes, target: tuple[str, int]) -> None:
        for _ in range(100):
            try:
                self._gvsp.sendto(packet, target)
                return
            except BlockingIOError:
                time.sleep(0.0005)
            except OSError:
                return

    def _resend(self, payload: bytes) -> None:
        _, block_id, first, last = struct.unpack(">HHII", payload[:12])
        packets, lost = self._stream.history.get(block_id, (None, None))
        target = self._stream_target()
        if packets is None or target is None:
            return
        for pid in range(first & 0xFFFFFF, min(last & 0xFFFFFF, len(packets) - 1) + 1):
            if pid != lost:
                self._send(packets[pid], target)


@dataclass
class _Control:
    privilege: int = 0
    peer: tuple[str, int] | None = None
    last_seen: float = 0.0


class _StreamState:
    def __init__(self) -> None:
        self.running = False
        self.triggers = 0
        self.block_id = 0
        self.history: dict[int, tuple[list[bytes], int | None]] = {}

    def start(self) -> None:
        self.triggers = 0
        self.running = True
