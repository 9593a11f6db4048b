"""Simulated serial instruments, each in its own process behind a real pseudo-terminal.

A simulator owns a pty pair (``os.openpty``, raw mode) and publishes the slave device through a
stable symlink (e.g. ``<dir>/light``): drivers open the symlink with pyserial, exactly as they would
open ``/dev/ttyUSB0``. When the port "vanishes" the simulator closes the pty, removes the symlink,
waits, opens a fresh pty and re-points the symlink (a pty path cannot be re-created).

The simulators are test equipment and must not fall over, whatever a client sends:

- a command line longer than `MAX_LINE_BYTES` is discarded unread and answered with one ``ERR 101``
  (never echoed back); error messages quote at most 32 characters of what was sent;
- replies go out through a non-blocking master and a bounded output buffer (`MAX_PENDING_OUTPUT_BYTES`):
  a client that writes without reading loses the replies beyond it, and the simulator keeps serving;
- fault counts are bounded (1 to `MAX_FAULT_COUNT`) and queued as (fault, count) pairs.

Fault injection, by command (never faulted itself; docs/serial-protocol.md):

- ``SIM:FAULT <name> [count]`` — the next ``count`` (default 1) commands get fault ``name``:
  ``noreply`` (command applied, reply lost), ``garbage`` (binary junk line instead of the reply),
  ``partial`` (first half of the reply, no terminator), ``err`` (``ERR 300``), ``busy`` (``ERR 200``),
  ``reset`` (instrument resets, sends its banner, command lost), ``vanish`` (port disappears for
  ``vanish_s`` and comes back as a new pty; command lost). ``SIM:FAULT NONE`` clears the queue.
- ``SIM:RESET`` — a spontaneous reset: ``OK``, then the banner, as if the instrument rebooted.

Every received line can be appended to a command log file (tests check what reached the device), and
every instrument logs its true state (`uwlab.sim.state_log`) to ``<dir>/<name>.state.jsonl``.
`SerialRig.kill` / `SerialRig.restart` cut an instrument's power and bring it back (fault campaigns);
`SerialRig.revive` restarts any simulator that died.
"""

from __future__ import annotations

import fcntl
import multiprocessing
import os
import select
import signal
import time
import threading
import tty
from collections import deque
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from collections.abc import Callable

from uwlab.drivers.serial.protocol import (
    ERR_BAD_ARGUMENT,
    ERR_BUSY,
    ERR_HARDWARE,
    ERR_OUT_OF_RANGE,
    MAX_LINE_BYTES,
    TERMINATOR,
)
from uwlab.sim.rig_state import LightState, RigState, WarmUp
from uwlab.sim.scene import load_scene
from uwlab.sim.devices.serial_instruments import (
    SimInstrument,
    SimLight,
    SimSpectrometer,
    SpectrumSource,
)
from uwlab.sim.state_log import StateLog
from uwlab.errors import ConfigError, DeviceError, UwlabError
from uwlab.model.evaluation import SPECTROMETER_POSITIONS

FAULTS = ("noreply", "garbage", "partial", "err", "busy", "reset", "vanish")
MAX_FAULT_COUNT = 10_000
MAX_PENDING_OUTPUT_BYTES = 64 * 1024
READ_CHUNK_BYTES = 4096
GARBAGE = b"\x00\xff\xfe\x1b[2J\xc3(\x07garbage\x80"
START_TIMEOUT_S = 60.0


class PtyPort:
    """The master side of a pty whose slave is published at the symlink ``link``.

    The master is non-blocking; replies wait in a bounded output buffer until the pty accepts them.
    """

    def __init__(self, link: Path):
        self.link = Path(link)
        self._pending = bytearray()
        self.dropped_bytes = 0
        self._open()

    def _open(self) -> None:
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        fcntl.fcntl(self.master, fcntl.F_SETFL, fcntl.fcntl(self.master, fcntl.F_GETFL) | os.O_NONBLOCK)
        temporary = self.link.with_name(f".{self.link.name}.new")
        temporary.unlink(missing_ok=True)
        os.symlink(os.ttyname(self._slave), temporary)
        os.replace(temporary, self.link)

    def close(self) -> None:
        self.link.unlink(missing_ok=True)
        self._pending.clear()
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass

    def vanish(self, seconds: float) -> None:
        """Disappear for ``seconds``, then come back on a new pty at the same symlink."""
        self.close()
        time.sleep(seconds)
        self._open()

    def read(self, timeout_s: float) -> bytes:
        """Input received within ``timeout_s`` (b"" if none); pending output is sent meanwhile."""
        writing = [self.master] if self._pending else []
        readable, writable, _ = select.select([self.master], writing, [], timeout_s)
        if writable:
            self._flush()
        if not readable:
            return b""
        try:
            return os.read(self.master, READ_CHUNK_BYTES)
        except BlockingIOError:
            return b""

    def write(self, data: bytes) -> None:
        """Queue ``data`` and send what the pty accepts now; beyond the bounded buffer, data is dropped."""
        room = MAX_PENDING_OUTPUT_BYTES - len(self._pending)
        self._pending += data[: max(room, 0)]
        self.dropped_bytes += max(len(data) - max(room, 0), 0)
        self._flush()

    def _flush(self) -> None:
        try:
            while self._pending:
                sent = os.write(self.master, self._pending)
                del self._pending[:sent]
        except (BlockingIOError, InterruptedError):
            pass


class SerialServer:
    """Read command lines from a `PtyPort`, answer with an instrument, inject the queued faults."""

    def __init__(
        self, instrument: SimInstrument, port: PtyPort, command_log: Path | None = None, vanish_s: float = 0.5
    ):
        self.instrument = instrument
        self.port = port
        self.command_log = command_log
        self.vanish_s = vanish_s
        self.faults: deque[list] = deque()
        self._buffer = b""
        self._overlong = False

    def step(self, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` for input and answer every complete line."""
        self._buffer += self.port.read(timeout_s)
        while TERMINATOR in self._buffer:
            raw, _, self._buffer = self._buffer.partition(TERMINATOR)
            if self._overlong or len(raw) > MAX_LINE_BYTES:
                self._overlong = False
                self._log(f"<command longer than {MAX_LINE_BYTES} bytes>")
                self._send([f"ERR {ERR_BAD_ARGUMENT} command longer than {MAX_LINE_BYTES} bytes\n".encode()])
                continue
            line = raw.decode("ascii", "replace").strip()
            if line:
                self._log(line)
                self._send(self.respond(line))
        if len(self._buffer) > MAX_LINE_BYTES:
            self._buffer = b""
            self._overlong = True

    def respond(self, line: str) -> list[bytes]:
        """Reply lines (terminated) for one command, after any queued fault."""
        header, _, argument = line.partition(" ")
        if header.upper() == "SIM:FAULT":
            return [self._queue_faults(argument.split())]
        if header.upper() == "SIM:RESET":
            self.instrument.power_on()
            return [b"OK\n", self.instrument.banner.encode() + TERMINATOR]
        try:
            if self.faults:
                return self._fault(self._next_fault(), line)
            return [reply.encode() + TERMINATOR for reply in self.instrument.handle(line)]
        except Exception as exc:  # a simulator bug or model error must not kill the port: report it as hardware
            return [f"ERR {ERR_HARDWARE} internal: {type(exc).__name__}: {exc}".encode()[:200] + TERMINATOR]

    def _queue_faults(self, fields: list[str]) -> bytes:
        if fields and fields[0].upper() == "NONE":
            self.faults.clear()
            return b"OK\n"
        valid_count = len(fields) == 1 or (len(fields) == 2 and fields[1].isascii() and fields[1].isdigit())
        if not fields or fields[0].lower() not in FAULTS or not valid_count:
            return f"ERR {ERR_BAD_ARGUMENT} expected SIM:FAULT <{'|'.join(FAULTS)}|NONE> [count]\n".encode()
        count = int(fields[1]) if len(fields) == 2 else 1
        if not 1 <= count <= MAX_FAULT_COUNT:
            return f"ERR {ERR_OUT_OF_RANGE} fault count outside [1, {MAX_FAULT_COUNT}]\n".encode()
        self.faults.append([fields[0].lower(), count])
        return b"OK\n"

    def _next_fault(self) -> str:
        fault = self.faults[0]
        fault[1] -= 1
        if fault[1] == 0:
            self.faults.popleft()
        return fault[0]

    def _fault(self, fault: str, line: str) -> list[bytes]:
        if fault == "noreply":
            self.instrument.handle(line)
            return []
        if fault == "garbage":
            return [GARBAGE + TERMINATOR]
        if fault == "partial":
            reply = self.instrument.handle(line)[0].encode()
            return [reply[: max(1, len(reply) // 2)]]
        if fault == "err":
            return [f"ERR {ERR_HARDWARE} simulated hardware fault\n".encode()]
        if fault == "busy":
            return [f"ERR {ERR_BUSY} busy\n".encode()]
        if fault == "reset":
            self.instrument.power_on()
            return [self.instrument.banner.encode() + TERMINATOR]
        self.port.vanish(self.vanish_s)
        self._buffer = b""
        return []

    def _send(self, replies: list[bytes]) -> None:
        if replies:
            self.port.write(b"".join(replies))

    def _log(self, line: str) -> None:
        if self.command_log is not None:
            with open(self.command_log, "a") as fh:
                fh.write(line + "\n")


def _child_main(factory, link: Path, command_log: Path | None, vanish_s: float, status, stop) -> None:
    """Process entry point: build the instrument, serve until ``stop`` is set, SIGTERM arrives or the parent dies."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        server = SerialServer(factory(), PtyPort(link), command_log, vanish_s)
    except (UwlabError, OSError) as exc:
        status.send(f"{type(exc).__name__}: {exc}")
        return
    status.send("ready")
    parent = multiprocessing.parent_process()
    assert parent is not None  # the simulator runs in a child process
    try:
        while not stop.is_set() and parent.is_alive():
            server.step(0.1)
    finally:
        server.port.close()


@contextmanager
def _ctrl_c_deferred():
    """Spawn children that never see Ctrl-C, and let the parent see it only once they are spawned.

    Ctrl-C reaches the whole process group. A child spawned inside this block starts with SIGINT blocked (the
    thread's mask survives fork and exec; `_child_main` then ignores it), so it prints no traceback while it is
    still importing. In the parent, the signal may land on any thread (pyarrow's, say), so blocking it in this
    one is not enough: Python's handler is swapped for one that only notes it, and KeyboardInterrupt is raised
    after the block — never halfway through a spawn, which would leave the child without its start-up data.
    Outside the main thread (no signal handlers there) the block only masks."""
    main = threading.current_thread() is threading.main_thread()
    noted = []
    previous = signal.signal(signal.SIGINT, lambda *_: noted.append(True)) if main else None
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        if main:
            signal.signal(signal.SIGINT, previous)
    if noted:
        raise KeyboardInterrupt


class SimulatorProcess:
    """One simulated instrument in a spawned process; ``link`` is its port path once started."""

    def __init__(
        self,
        factory: Callable[[], SimInstrument],
        link: Path,
        *,
        command_log: Path | None = None,
        vanish_s: float = 0.5,
    ):
        context = multiprocessing.get_context("spawn")
        self.link = Path(link)
        self._options = (factory, command_log, vanish_s)
        self._status, child_status = context.Pipe(duplex=False)
        self._stop = context.Event()  # polled by the child; see `stop` for why the parent sets it only while it runs
        self._stopped = False  # stop() was called
        self.process = context.Process(
            target=_child_main,
            args=(factory, self.link, command_log, vanish_s, child_status, self._stop),
            daemon=True,
        )

    @property
    def port(self) -> str:
        return str(self.link)

    @property
    def died(self) -> bool:
        """Started, and no longer running although nobody stopped it."""
        return self.process.pid is not None and not self._stopped and not self.process.is_alive()

    def fresh(self) -> SimulatorProcess:
        """A new, unstarted simulator of the same instrument on the same port path."""
        factory, command_log, vanish_s = self._options
        return SimulatorProcess(factory, self.link, command_log=command_log, vanish_s=vanish_s)

    def kill(self, timeout_s: float = 10.0) -> None:
        """SIGKILL, as a power cut: no clean-up by the process; its port disappears (as a USB device's node does)."""
        if self.process.is_alive():
            self.process.kill()
        self.process.join(timeout_s)
        self.link.unlink(missing_ok=True)

    def start(self, timeout_s: float = START_TIMEOUT_S) -> SimulatorProcess:
        with _ctrl_c_deferred():
            self.process.start()
        deadline = time.monotonic() + timeout_s
        while not self._status.poll(0.1):
            if not self.process.is_alive() or time.monotonic() > deadline:
                self.stop()
                raise DeviceError(f"simulator for {self.link} did not start (exit code {self.process.exitcode})")
        try:
            status = self._status.recv()
        except EOFError:
            status = f"exited (code {self.process.exitcode}) before it was ready"
        if status != "ready":
            self.stop()
            raise DeviceError(f"simulator for {self.link} failed to start: {status}")
        return self

    def stop(self, timeout_s: float = 10.0) -> None:
        """Ask the process to finish, then terminate and kill it if it does not.

        The stop event is set only while the process runs: one killed (SIGKILL, a power cut) while it polled the
        event may have died holding the event's lock, and setting it would then wait for ever (a CI run hung in a
        fixture's teardown so, after the random-restart sweep)."""
        self._stopped = True
        if self.process.pid is None:
            return
        if self.process.is_alive():
            self._stop.set()
        self.process.join(timeout_s)
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout_s)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(timeout_s)
        self.link.unlink(missing_ok=True)

    def __enter__(self) -> SimulatorProcess:
        return self.start() if self.process.pid is None else self

    def __exit__(self, *exc_info) -> None:
        self.stop()


@dataclass(frozen=True)
class SerialSimSettings:
    """What the serial simulators take from the rig: the config, the light's gamma and warm-up, the spectrometer
    position."""

    config_path: Path | None = None
    light_gamma: float = 2.2
    spectrometer_position: str = "target"
    warm_up: WarmUp = WarmUp()

    @classmethod
    def from_config(cls, path: str | os.PathLike | None, spectrometer_position: str = "target") -> SerialSimSettings:
        """Load and check the rig config (None: the default rig) and take its ``[sim] light_gamma``."""
        if spectrometer_position not in SPECTROMETER_POSITIONS:
            raise ConfigError(
                "spectrometer_position", spectrometer_position, f"must be one of {', '.join(SPECTROMETER_POSITIONS)}"
            )
        scene = load_scene(None if path is None else Path(path))
        return cls(
            Path(path) if path is not None else None, scene.sim.light_gamma, spectrometer_position, scene.warm_up()
        )


class SceneSpectrum:
    """`SpectrumSource` from the rig model (`uwlab.sim.scene.load_scene`: the tank or the EMVA bench), built
    on first use."""

    def __init__(self, config_path: Path | None):
        self.config_path = config_path
        self._scene = None

    def __call__(self, position: str, flux_fraction: float):
        scene = self._scene
        if scene is None:
            scene = self._scene = load_scene(self.config_path)
        return scene.spectral_irradiance(position, flux_fraction)


def _make_light(rig_state_path: Path, gamma: float, state_log: Path, warm_up: WarmUp) -> SimLight:
    return SimLight(RigState(rig_state_path), gamma, state_log=StateLog(state_log), drift=warm_up)


def _make_spectrometer(
    rig_state_path: Path, spectrum: SpectrumSource, position: str, seed: int | None, state_log: Path
):
    return SimSpectrometer(RigState(rig_state_path), spectrum, position, seed=seed, state_log=StateLog(state_log))


class SerialRig:
    """The simulated light and spectrometer sharing one rig state file in ``directory``.

    Ports: ``<directory>/light`` and ``<directory>/spectrometer``; rig state: ``<directory>/rig-state.json``;
    true-state logs: ``<directory>/<name>.state.jsonl`` (`state_log`).
    ``spectrum`` replaces the rig model (tests inject a known one); it must be picklable.
    With ``command_log``, each simulator appends received lines to ``<directory>/<name>.log``.
    """

    def __init__(
        self,
        directory: str | os.PathLike,
        settings: SerialSimSettings = SerialSimSettings(),
        *,
        spectrum: SpectrumSource | None = None,
        seed: int | None = None,
        command_log: bool = False,
        vanish_s: float = 0.5,
    ):
        self.directory = Path(directory)
        self.rig_state_path = self.directory / "rig-state.json"
        spectrum = spectrum if spectrum is not None else SceneSpectrum(settings.config_path)
        factories = {
            "light": partial(
                _make_light, self.rig_state_path, settings.light_gamma, self.state_log("light").path, settings.warm_up
            ),
            "spectrometer": partial(
                _make_spectrometer,
                self.rig_state_path,
                spectrum,
                settings.spectrometer_position,
                seed,
                self.state_log("spectrometer").path,
            ),
        }
        self.simulators = {
            name: SimulatorProcess(
                factory,
                self.directory / name,
                command_log=self.log_path(name) if command_log else None,
                vanish_s=vanish_s,
            )
            for name, factory in factories.items()
        }

    def log_path(self, name: str) -> Path:
        return self.directory / f"{name}.log"

    def state_log(self, name: str) -> StateLog:
        """The true-state log of simulator ``name`` (kept across its restarts)."""
        return StateLog(self.directory / f"{name}.state.jsonl")

    def kill(self, name: str) -> None:
        """Cut simulator ``name``'s power: SIGKILL; the light goes dark. Logged as ``power-lost``."""
        self.simulators[name].kill()
        self._power_lost(name)

    def restart(self, name: str) -> None:
        """Start simulator ``name`` again on the same port path, at its power-on state."""
        self.simulators[name].stop()
        self.simulators[name] = self.simulators[name].fresh().start()

    def revive(self) -> dict[str, int | None]:
        """Restart every simulator that died unasked (logged as a power loss); returns their exit codes."""
        dead = {name: sim.process.exitcode for name, sim in self.simulators.items() if sim.died}
        for name in dead:
            self._power_lost(name)
            self.restart(name)
        return dead

    def _power_lost(self, name: str) -> None:
        if name == "light":
            RigState(self.rig_state_path).set_light(LightState(False, 0.0, 0.0))
            self.state_log(name).append("power-lost", on=False, level=0.0, flux_fraction=0.0)
        else:
            self.state_log(name).append("power-lost")

    @property
    def ports(self) -> dict[str, str]:
        return {name: simulator.port for name, simulator in self.simulators.items()}

    def start(self) -> SerialRig:
        try:
            for simulator in self.simulators.values():
                simulator.start()
        except BaseException:
            self.stop()
            raise
        return self

    def stop(self) -> None:
        for simulator in self.simulators.values():
            simulator.stop()

    def __enter__(self) -> SerialRig:
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.stop()
