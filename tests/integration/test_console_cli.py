"""`uwlab console`: prints its URL on one line, serves the rig's JSON API there, stops on Ctrl-C with one line and
130 (the simulated light read back off: its safe state); bad input is one line and exit 2 before any device opens."""

import socket

import httpx2

from tests.support.cli import one_line_error
from tests.support.console_process import Console
from tests.support.paths import SIM_TANK


def test_serves_the_rig_and_stops_on_ctrl_c():
    console = Console("--sim")
    try:
        assert console.url.startswith("http://127.0.0.1:")
        rig = httpx2.get(console.url + "api/rig", timeout=30).json()
        assert rig["camera"]["width"] == 2448 and rig["lights"]["light"]["on"] is False
        on = httpx2.post(console.url + "api/lights/light", json={"on": True, "level": 0.5}, timeout=30).json()
        assert on["on"] is True and on["level"] == 0.5
    finally:
        code, err = console.stop()
    assert code == 130 and err == "uwlab console: interrupted\n"


def run_error(capsys, *argv) -> str:
    return one_line_error(capsys, ["console", "--no-browser", *argv])


def test_bad_inputs_are_one_line(capsys, tmp_path):
    assert "--sim" in run_error(capsys)
    assert "simulated only" in run_error(capsys, str(SIM_TANK))
    assert "file not found" in run_error(capsys, str(tmp_path / "none.toml"), "--sim")
    assert "--max-fps" in run_error(capsys, "--sim", "--max-fps", "0")
    assert "--port" in run_error(capsys, "--sim", "--port", "70000")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        assert "--port" in run_error(capsys, "--sim", "--port", str(busy.getsockname()[1]))
