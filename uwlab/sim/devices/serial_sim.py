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
import os
import pickle
import select
import signal
import subprocess
import sys
import time
import tty
from collections import deque
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
MODULE = "uwlab.sim.devices.serial_sim"  # a simulator process runs ``python -P -m MODULE``


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


def _serve(status: int) -> None:
    """The simulator process's work: read the instrument to simulate, build it, report ``ready`` (or why not) on
    the pipe ``status``, then serve until its standard input (the parent's lifeline) reaches its end:
    `SimulatorProcess.stop` closes it, and the kernel closes it when the parent dies, however it dies. SIGTERM
    stops it too. A parent that stopped listening (interrupted while it started) ends it quietly."""
    stopping: list[bool] = []
    signal.signal(signal.SIGTERM, lambda *_: stopping.append(True))
    try:
        sys.path[:] = pickle.load(sys.stdin.buffer)  # the factory's modules are found as in the parent
        factory, link, command_log, vanish_s = pickle.load(sys.stdin.buffer)
    except EOFError:  # the parent went away before it sent them
        return
    except Exception as exc:  # e.g. a spectrum defined in the caller's __main__, which is not imported here
        _report(status, f"cannot load the instrument: {type(exc).__name__}: {exc}")
        return
    try:
        server = SerialServer(factory(), PtyPort(link), command_log, vanish_s)
    except (UwlabError, OSError) as exc:
        _report(status, f"{type(exc).__name__}: {exc}")
        return
    try:
        if not _report(status, "ready"):
            return
        lifeline = sys.stdin.fileno()
        while not stopping and not select.select([lifeline], [], [], 0)[0]:  # readable: at its end
            server.step(0.1)
    finally:
        server.port.close()


def _report(status: int, line: str) -> bool:
    """Write the start-up outcome and close the pipe; False when nobody reads it any more."""
    try:
        os.write(status, line.encode(errors="replace") + b"\n")
        return True
    except BrokenPipeError:
        return False
    finally:
        os.close(status)


def main() -> None:
    """``python -P -m uwlab.sim.devices.serial_sim STATUS_FD``, started by `SimulatorProcess`: two pickles on
    standard input (the parent's ``sys.path``, then the instrument factory and its options), the outcome of the
    start as one line on the file descriptor STATUS_FD."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # its own process group; a stray SIGINT must not kill it either
    _serve(int(sys.argv[1]))


class SimulatorProcess:
    """One simulated instrument in a process of its own (``python -m uwlab.sim.devices.serial_sim``, never a
    multiprocessing child: starting one does not import the caller's ``__main__`` again, so a script without an
    ``if __name__ == "__main__":`` guard is not re-run); ``link`` is its port path once started.

    The factory (and what it holds) is pickled to the process, which imports its modules from the parent's
    ``sys.path``. The process runs in its own process group (a terminal's Ctrl-C reaches the parent only, which
    stops it) and ends when its standard input closes: on `stop`, or when the parent dies."""

    def __init__(
        self,
        factory: Callable[[], SimInstrument],
        link: Path,
        *,
        command_log: Path | None = None,
        vanish_s: float = 0.5,
    ):
        self.link = Path(link)
        self._options = (factory, command_log, vanish_s)
        self.process: subprocess.Popen[bytes] | None = None
        self._stopped = False  # stop() was called

    @property
    def port(self) -> str:
        return str(self.link)

    @property
    def exitcode(self) -> int | None:
        """The process's exit code (negative: the signal that ended it); None while it runs or before it starts."""
        return None if self.process is None else self.process.poll()

    @property
    def died(self) -> bool:
        """Started, and no longer running although nobody stopped it."""
        return self.process is not None and not self._stopped and self.exitcode is not None

    def fresh(self) -> SimulatorProcess:
        """A new, unstarted simulator of the same instrument on the same port path."""
        factory, command_log, vanish_s = self._options
        return SimulatorProcess(factory, self.link, command_log=command_log, vanish_s=vanish_s)

    def kill(self, timeout_s: float = 10.0) -> None:
        """SIGKILL, as a power cut: no clean-up by the process; its port disappears (as a USB device's node does)."""
        if self.process is not None:
            if self.process.poll() is None:
                self.process.kill()
            self.process.wait(timeout_s)
        self.link.unlink(missing_ok=True)

    def start(self, timeout_s: float = START_TIMEOUT_S) -> SimulatorProcess:
        factory, command_log, vanish_s = self._options
        payload = pickle.dumps(list(sys.path)) + pickle.dumps((factory, self.link, command_log, vanish_s))
        status_read, status_write = os.pipe()
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-P", "-m", MODULE, str(status_write)],
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
                pass_fds=(status_write,),
                process_group=0,
                env=_child_environment(),
            )
            os.close(status_write)
            status_write = -1
            status = self._handshake(payload, status_read, timeout_s)
        except BaseException:  # Ctrl-C while it starts, say: the process must not outlive the attempt
            self.stop()
            raise
        finally:
            os.close(status_read)
            if status_write >= 0:
                os.close(status_write)
        if status != "ready":
            self.stop()
            raise DeviceError(f"simulator for {self.link} failed to start: {status}")
        return self

    def _handshake(self, payload: bytes, status_fd: int, timeout_s: float) -> str:
        """Send the start-up data; the status line the process answers (or why there is none)."""
        assert self.process is not None and self.process.stdin is not None
        try:
            self.process.stdin.write(payload)
            self.process.stdin.flush()
        except BrokenPipeError:
            pass  # the process ended early: its status (or exit code) says why
        received = b""
        deadline = time.monotonic() + timeout_s
        while not received.endswith(b"\n"):
            if not select.select([status_fd], [], [], max(deadline - time.monotonic(), 0.0))[0]:
                return f"not ready within {timeout_s:g} s"
            chunk = os.read(status_fd, 4096)
            if not chunk:
                return f"exited (code {self.process.wait(timeout_s)}) before it was ready"
            received += chunk
        return received.decode(errors="replace").strip()

    def stop(self, timeout_s: float = 10.0) -> None:
        """Close the process's lifeline and wait for it to finish; terminate, then kill it if it does not."""
        self._stopped = True
        process = self.process
        if process is None:
            return
        if process.stdin is not None:
            try:
                process.stdin.close()
            except BrokenPipeError:
                pass
        for end in (None, process.terminate, process.kill):
            if end is not None and process.poll() is None:
                end()
            try:
                process.wait(timeout_s)
                break
            except subprocess.TimeoutExpired:
                continue
        self.link.unlink(missing_ok=True)

    def __enter__(self) -> SimulatorProcess:
        return self.start() if self.process is None else self

    def __exit__(self, *exc_info) -> None:
        self.stop()


def _child_environment() -> dict[str, str]:
    """The environment for a simulator process: this one's, with the directory holding this uwlab first on
    PYTHONPATH (the process must import the same uwlab, wherever the caller's script runs)."""
    root = str(Path(__file__).resolve().parents[3])
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([root, *filter(None, env.get("PYTHONPATH", "").split(os.pathsep))])
    return env


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
        dead = {name: sim.exitcode for name, sim in self.simulators.items() if sim.died}
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


if __name__ == "__main__":
    main()
