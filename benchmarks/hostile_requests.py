"""Hostile-request campaign against `uwlab explore` (a real process on 127.0.0.1 with a token): odd paths, Host
headers, tokens and names meant to make it fail or redirect off-site; every file-valued key and endpoint naming
files planted outside its folders; connections held open by silent and slow clients while a normal client keeps
asking. Prints one JSON object of counts.

Targets (issue 36): 0 answers with status 500, 0 file contents returned or quoted, 0 off-site redirects, every held
connection closed within 30 s, normal requests answered in ≤ 1 s throughout.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path
from urllib.parse import urlsplit

import httpx2

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support.explorer_process import (  # noqa: E402
    SECRET,
    Explorer,
    file_probes,
    held_connections,
    hostile_requests,
    offsite,
    plant_secrets,
    raw_request,
)

EXAMPLE = ROOT / "configs" / "design" / "example.toml"
TOKEN = "hostile-benchmark-token"
HELD = 100
LIMIT_S = 60.0


def main() -> dict:
    explorer = Explorer(str(EXAMPLE), "--token", TOKEN)
    statuses: dict[int, int] = {}
    failures: list[str] = []
    leaked = redirected = cookies = tried = 0
    try:
        port = urlsplit(explorer.url).port
        assert port is not None
        for name, request in hostile_requests(port, TOKEN):
            status, headers, body = raw_request(port, request)
            tried += 1
            statuses[status] = statuses.get(status, 0) + 1
            redirected += offsite(headers.get("location"))
            cookie = headers.get("set-cookie", "")
            foreign = bool(cookie) and not cookie.startswith((f"uwlab_token={TOKEN};", "_xsrf="))
            cookies += foreign
            if status >= 500 or status == 0 or offsite(headers.get("location")) or foreign:
                failures.append(f"{name} → {status}")
        with (
            tempfile.TemporaryDirectory() as tmp,
            httpx2.Client(
                base_url=f"http://127.0.0.1:{port}", headers={"Authorization": f"token {TOKEN}"}, timeout=60
            ) as client,
        ):
            for name, path, body_json in file_probes(plant_secrets(Path(tmp) / "outside")):
                answer = client.post(path, json=body_json)
                tried += 1
                statuses[answer.status_code] = statuses.get(answer.status_code, 0) + 1
                if SECRET in answer.text or "hunter2" in answer.text:
                    leaked += 1
                    failures.append(f"{name}: file content in the answer")
                if answer.is_success or answer.status_code >= 500:
                    failures.append(f"{name} → {answer.status_code}")

            def probe() -> float | None:
                started = time.monotonic()
                try:
                    ok = client.get("/api/config", timeout=30).status_code == 200
                except httpx2.HTTPError:
                    return None
                return time.monotonic() - started if ok else None

            held = held_connections(port, HELD, LIMIT_S, probe)
    finally:
        code, err = explorer.stop()
    return {
        "benchmark": "hostile_requests",
        "requests_tried": tried,
        "answers_500": sum(n for s, n in statuses.items() if s >= 500),
        "file_contents_leaked": leaked,
        "offsite_redirects": redirected,
        "foreign_cookies": cookies,
        "statuses": {str(s): n for s, n in sorted(statuses.items())},
        "held_connections": held["held"],
        "held_connections_closed": held["closed"],
        "worst_close_s": held["worst_close_s"],
        "normal_requests": held["probes"],
        "normal_requests_failed": held["probes_failed"],
        "worst_normal_latency_s": held["worst_probe_s"],
        "failures": failures,
        "server_exit": code,
        "server_tracebacks": err.count("Traceback"),
    }


if __name__ == "__main__":
    print(json.dumps(main(), indent=1))
