"""`uwlab explore`: prints its URL (one JSON line with --json), serves the page and the API there, stops on Ctrl-C
with one line and 130; a bad config, a busy port or a bad profile is one line and exit 2 before anything runs."""

import json
import socket

import httpx2
import pytest

from uwlab.cli.main import main

from tests.support.cli import one_line_error
from tests.support.paths import EXAMPLE
from tests.support.explorer_process import Explorer


def test_serves_the_page_and_the_api_and_stops_on_ctrl_c():
    explorer = Explorer(str(EXAMPLE))
    try:
        assert explorer.url.startswith("http://127.0.0.1:")
        page = httpx2.get(explorer.url, timeout=30)
        assert page.status_code == 200 and "uwlab" in page.text and 'data-key="lens.f_number"' in page.text
        answer = httpx2.post(explorer.url + "api/design", json={"set": {"lens.f_number": 4}}, timeout=30)
        assert answer.status_code == 200 and answer.json()["snr_db"] > 0
    finally:
        code, err = explorer.stop()
    assert code == 130 and err == "uwlab explore: interrupted\n"


def run_error(capsys, *argv) -> str:
    return one_line_error(capsys, ["explore", "--no-browser", *argv])


def test_bad_inputs_are_one_line(capsys, tmp_path):
    assert "file not found" in run_error(capsys, str(tmp_path / "none.toml"))
    bad = tmp_path / "bad.toml"
    bad.write_text(EXAMPLE.read_text().replace("f_number = 2.0", "f_number = 0.02"))
    assert "lens.f_number = 0.02" in run_error(capsys, str(bad))
    assert "--port" in run_error(capsys, str(EXAMPLE), "--port", "70000")
    assert "--host" in run_error(capsys, str(EXAMPLE), "--host", "no.such.host.invalid")
    assert "profile" in run_error(capsys, str(EXAMPLE), "--profile", str(EXAMPLE))
    assert "--token" in run_error(capsys, str(EXAMPLE), "--token", "abcdefgh; Domain=evil")
    assert "--allow-host" in run_error(capsys, str(EXAMPLE), "--allow-host", "lab-pc:80@evil.example")


def test_a_busy_port_is_one_line(capsys):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        err = run_error(capsys, str(EXAMPLE), "--port", str(port))
    assert f"--port = {port}" in err and "cannot listen" in err


@pytest.mark.parametrize("argv", [["--json"], []])
def test_url_line(argv, capsys, monkeypatch):
    """The URL is printed once the server has started: one JSON object with --json, a sentence otherwise."""
    import uvicorn

    async def started_then_stopped(self, sockets):
        self.started = True
        sockets[0].close()

    monkeypatch.setattr(uvicorn.Server, "serve", started_then_stopped)
    assert main(["explore", str(EXAMPLE), "--no-browser", "--port", "0", *argv]) == 0
    out = capsys.readouterr().out
    if argv:
        assert list(json.loads(out)) == ["url"]
    else:
        assert out.startswith("uwlab explore: ") and "http://127.0.0.1:" in out


def test_the_url_printed_for_a_wildcard_address_answers(capsys, monkeypatch):
    """--host 0.0.0.0 prints the loopback with the token (the wildcard is no address a browser may name), and the
    application the server was given serves that URL."""
    import uvicorn
    from starlette.testclient import TestClient

    served = {}

    async def started_then_stopped(self, sockets):
        served["app"] = self.config.app
        self.started = True
        sockets[0].close()

    monkeypatch.setattr(uvicorn.Server, "serve", started_then_stopped)
    assert main(["explore", str(EXAMPLE), "--no-browser", "--json", "--port", "0", "--host", "0.0.0.0"]) == 0
    url = json.loads(capsys.readouterr().out)["url"]
    assert url.startswith("http://127.0.0.1:") and "?token=" in url
    with TestClient(served["app"], base_url=url.split("?")[0]) as client:
        assert client.get(url).status_code == 200
