"""Hostile requests against a real `uwlab explore` process on 127.0.0.1 (our own probes, after the audit of issue
36): no answer is a 500, none redirects off the server or writes a cookie the server did not make, no file outside
the explorer's folders is quoted, and connections held open by slow or silent clients are closed by the server
while a normal request still answers. Counts and latencies: benchmarks/hostile_requests.py."""

from __future__ import annotations

import time
from urllib.parse import urlsplit

import httpx2
import pytest

from tests.support.explorer_process import (
    SECRET,
    Explorer,
    file_probes,
    held_connections,
    hostile_requests,
    offsite,
    plant_secrets,
    raw_request,
)
from tests.support.paths import EXAMPLE

TOKEN = "hostile-test-token"
HELD = 60  # held connections: more than one client may have (uwlab.explore.server.Limits.per_client)
TARGET_CLOSE_S = 30  # issue 36: held connections closed within 30 s


@pytest.fixture(scope="module")
def explorer():
    server = Explorer(str(EXAMPLE), "--token", TOKEN)
    yield server, urlsplit(server.url).port
    code, err = server.stop()
    assert code == 130 and "Traceback" not in err


def test_no_hostile_request_gets_a_500_an_offsite_redirect_or_a_foreign_cookie(explorer):
    _, port = explorer
    answers = {name: raw_request(port, request) for name, request in hostile_requests(port, TOKEN)}
    for name, (status, headers, _) in answers.items():
        assert 400 <= status < 500 or status in (200, 303), (name, status)
        assert not offsite(headers.get("location")), (name, headers.get("location"))
        cookie = headers.get("set-cookie", "")
        assert not cookie or cookie.startswith((f"uwlab_token={TOKEN};", "_xsrf=")), (name, cookie)
        assert "evil" not in cookie.lower(), name
    assert answers["non-Latin-1 path"][0] == 303 and answers["network-path redirect"][0] == 303
    for host in (f"127.0.0.1:{port}.evil.com", f"localhost:{port}@evil.com", f"[localhost]:{port}", "localhost:"):
        assert answers[f"Host {host!r}"][0] == 400, host


def test_no_file_outside_the_roots_is_quoted_over_http(explorer, tmp_path):
    _, port = explorer
    probes = file_probes(plant_secrets(tmp_path / "outside"))
    with httpx2.Client(base_url=f"http://127.0.0.1:{port}", headers={"Authorization": f"token {TOKEN}"}) as client:
        for name, path, body in probes[:: max(1, len(probes) // 120)]:  # every key and endpoint, a sample of names
            answer = client.post(path, json=body, timeout=60)
            assert answer.status_code == 422 and SECRET not in answer.text, (name, answer.status_code)


def test_held_connections_are_closed_while_normal_requests_answer(explorer):
    _, port = explorer
    client = httpx2.Client(base_url=f"http://127.0.0.1:{port}", headers={"Authorization": f"token {TOKEN}"})

    def probe() -> float | None:
        started = time.monotonic()
        try:
            ok = client.get("/api/config", timeout=30).status_code == 200
        except httpx2.HTTPError:
            return None
        return time.monotonic() - started if ok else None

    with client:
        result = held_connections(port, HELD, 2 * TARGET_CLOSE_S, probe)
    assert result["closed"] == HELD and result["worst_close_s"] <= TARGET_CLOSE_S, result
    assert result["probes"] > 0 and result["probes_failed"] == 0, result
