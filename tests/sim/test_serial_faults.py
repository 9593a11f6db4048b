"""Serial instruments that restart, and simulators that must not fall over: real ptys, pyserial, processes."""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

import pytest
import serial

from uwlab.drivers.serial import open_light, open_spectrometer
from uwlab.drivers.serial.base import LightReadback, SpectrometerReadback
from uwlab.sim.rig_state import RigState
from uwlab.sim.devices.serial_sim import MAX_FAULT_COUNT, SerialRig, SerialSimSettings
from uwlab.sim.state_log import states_during
from uwlab.errors import DeviceError

from tests.support.cli_process import read_line, uwlab

TIMEOUT_S = 0.75


def flat_spectrum(position: str, flux_fraction: float):
    """0.01 W/m²/nm from 350 to 800 nm at full flux."""
    return [350.0, 800.0], [0.01 * flux_fraction] * 2


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    with SerialRig(
        tmp_path_factory.mktemp("faults"), SerialSimSettings(light_gamma=2.0), spectrum=flat_spectrum, seed=3
    ) as rig:
        yield rig


def raw_port(rig: SerialRig, name: str) -> serial.Serial:
    """The instrument's port opened with plain pyserial (no driver: raw bytes in and out)."""
    return serial.serial_for_url(rig.ports[name], baudrate=115200, timeout=2.0, write_timeout=30.0)


def ask(port: serial.Serial, command: str) -> bytes:
    port.reset_input_buffer()
    port.write(command.encode() + b"\n")
    return port.readline()


def test_restarted_light_gets_its_state_back_verified_and_logged(rig):
    with open_light(rig.ports["light"], timeout_s=TIMEOUT_S, reopen_s=30.0) as light:
        light.set_output(True)
        light.set_level(0.7)
        recoveries = light.recoveries
        rig.kill("light")
        assert RigState(rig.rig_state_path).light.effective_fraction == 0.0
        rig.restart("light")
        t_restarted = time.time_ns()
        assert light.readback() == LightReadback(True, 0.7)
        assert light.recoveries == recoveries + 1
        assert RigState(rig.rig_state_path).light.level == 0.7
    events = rig.state_log("light").entries()
    lost = max(i for i, e in enumerate(events) if e["event"] == "power-lost")
    assert [e["event"] for e in events[lost : lost + 4]] == ["power-lost", "power-on", "command", "command"]
    assert (events[lost + 3]["on"], events[lost + 3]["level"]) == (True, 0.7)
    now = states_during(events, time.time_ns(), time.time_ns())[-1]
    assert (now["on"], now["level"]) == (True, 0.7) and events[lost + 1]["t_ns"] < t_restarted


def test_restarted_spectrometer_reads_with_the_settings_it_was_given(rig):
    with open_spectrometer(rig.ports["spectrometer"], timeout_s=TIMEOUT_S, reopen_s=30.0) as spectrometer:
        spectrometer.set_integration_ms(12.5)
        spectrometer.set_averaging(3)
        rig.kill("spectrometer")
        rig.restart("spectrometer")
        t_read = time.time_ns()
        spectrometer.read_spectrum()
        assert spectrometer.readback() == SpectrometerReadback(12.5, 3)
    reads = [e for e in rig.state_log("spectrometer").entries() if e["event"] == "read" and e["t_ns"] > t_read]
    assert [(e["integration_ms"], e["averaging"]) for e in reads] == [(12.5, 3)]


def test_a_port_path_that_now_leads_to_another_instrument_is_not_used(rig):
    """The spectrometer loses power and its device name comes back pointing at the light (USB re-enumeration, a
    reused pty): the driver lets go and waits for its own instrument instead of sending it the light's commands."""
    with open_spectrometer(rig.ports["spectrometer"], timeout_s=TIMEOUT_S, reopen_s=30.0) as spectrometer:
        spectrometer.set_integration_ms(20.0)
        light_events = len(rig.state_log("light").entries())
        rig.kill("spectrometer")
        os.symlink(os.path.realpath(rig.ports["light"]), rig.ports["spectrometer"])
        comes_back = threading.Timer(1.0, rig.restart, args=("spectrometer",))
        comes_back.start()
        assert spectrometer.readback() == SpectrometerReadback(20.0, 1)
        comes_back.join()
    assert spectrometer.identity_at_open.startswith("UWLAB,SIM-SPECTROMETER")
    assert len(rig.state_log("light").entries()) == light_events


def test_instrument_that_keeps_resetting_is_one_clear_error(rig):
    with open_light(rig.ports["light"], timeout_s=TIMEOUT_S) as light:
        light.set_level(0.2)
        light.transport.command("SIM:FAULT reset 50")
        with pytest.raises(DeviceError) as info:
            light.level()
        assert rig.ports["light"] in str(info.value) and "\n" not in str(info.value)
        light.transport.command("SIM:FAULT NONE")


def test_huge_fault_count_is_refused_and_the_simulator_lives_on(rig):
    with raw_port(rig, "light") as port:
        assert ask(port, "SIM:FAULT noreply 1000000000000").startswith(b"ERR 102")
        assert ask(port, f"SIM:FAULT noreply {MAX_FAULT_COUNT + 1}").startswith(b"ERR 102")
        assert ask(port, f"SIM:FAULT noreply {MAX_FAULT_COUNT}") == b"OK\n"
        assert ask(port, "SIM:FAULT NONE") == b"OK\n"
        assert ask(port, "*IDN?").startswith(b"UWLAB,SIM-LIGHT")
    assert not rig.simulators["light"].died


def test_overlong_command_is_refused_without_being_echoed(rig):
    with raw_port(rig, "light") as port:
        port.write(b"LEV " + b"9" * (1 << 20) + b"\n")
        assert port.readline() == b"ERR 101 command longer than 4096 bytes\n"
        reply = ask(port, "LEV " + "x" * 4000)
        assert reply.startswith(b"ERR 101 not a number: 'xxxx") and len(reply) < 100
        assert ask(port, "*IDN?").startswith(b"UWLAB,SIM-LIGHT")


def test_fractional_averaging_is_refused(rig):
    with raw_port(rig, "spectrometer") as port:
        before = ask(port, "SPEC:AVG?")
        for argument in ("2.5", "2e0", "0x2", "two"):
            assert ask(port, f"SPEC:AVG {argument}").startswith(b"ERR 101 not an integer")
        assert ask(port, "SPEC:AVG?") == before
        assert ask(port, "SPEC:AVG 2") == b"OK\n" and ask(port, "SPEC:AVG?") == b"2\n"


def test_client_that_never_reads_cannot_stall_the_simulator(rig):
    """64 KB of queries, then a setting, nothing read: the simulator drops what does not fit and goes on."""
    queries = 64 * 1024 // 6
    with raw_port(rig, "light") as port:
        assert ask(port, "LEV 0.5") == b"OK\n"
        port.write(b"*IDN?\n" * queries + b"LEV 0.25\n")
        port.flush()
        deadline = time.monotonic() + 20.0
        while RigState(rig.rig_state_path).light.level != 0.25 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert RigState(rig.rig_state_path).light.level == 0.25, "the simulator stalled behind unread replies"
        port.timeout = 0.5
        replies = port.readlines()
        assert 0 < sum(r.startswith(b"UWLAB,SIM-LIGHT") for r in replies) < queries
        assert ask(port, "LEV?") == b"0.25\n"


def _children(pid: int) -> list[int]:
    return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]


def _holder_of(pty: str, pids: list[int]) -> int:
    """The process holding the pty slave ``pty`` open (the simulator publishing it)."""
    for pid in pids:
        for fd in Path(f"/proc/{pid}/fd").iterdir():
            try:
                if os.readlink(fd) == pty:
                    return pid
            except OSError:
                continue
    raise AssertionError(f"no process holds {pty}")


def test_sim_serial_restarts_a_dead_simulator_then_stops_on_a_crash_loop():
    process = uwlab("sim", "serial", "--json")
    try:
        info = json.loads(read_line(process.stdout, 120, "uwlab sim serial"))
        for death in range(1, 5):
            pid = _holder_of(os.path.realpath(info["light"]), _children(process.pid))
            os.kill(pid, signal.SIGKILL)
            line = read_line(process.stderr, 60, "uwlab sim serial's stderr")
            if death <= 3:
                assert line == (
                    f"uwlab sim serial: the light simulator died (exit code -9); restarted at its "
                    f"power-on state on {info['light']}\n"
                )
                with open_light(info["light"], timeout_s=2.0) as light:
                    assert light.readback() == LightReadback(False, 0.0)
                    with pytest.raises(DeviceError, match="ERR 102"):
                        light.transport.command("SIM:FAULT noreply 1000000000000")
        assert line == "uwlab sim: error: the light simulator died 4 times within 60 s (last exit code -9); stopping\n"
        assert process.wait(timeout=60) == 2
        assert not os.path.lexists(info["light"]) and not os.path.lexists(info["spectrometer"])
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(timeout=30)
        process.stdout.close()
        process.stderr.close()
