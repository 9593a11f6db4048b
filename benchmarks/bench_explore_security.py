"""Explorer security campaign and load: hostile requests against `uwlab explore` (a real process on 127.0.0.1),
then design requests from 20 concurrent clients. Prints one JSON object.

Targets (issue 25): 0 hostile requests succeed (a success is any 2xx answer, or an answer quoting a secret file);
≥ 300 design requests/s with 20 clients, p99 ≤ 100 ms, the server's memory flat (RSS after ≈ before).
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from urllib.parse import parse_qsl, urlsplit

import httpx2
import psutil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support.explorer_process import Explorer  # noqa: E402

EXAMPLE = ROOT / "configs" / "design" / "example.toml"
SECRET = "SECRET-TOKEN-abc123"
CLIENTS = 20
LOAD_S = 10.0


def hostile(base: str, secret: Path) -> list[tuple[str, str, dict]]:
    """(name, method + path, httpx2 request options) of every hostile request."""
    origin = {"Origin": "http://evil.example"}
    plain = {"Content-Type": "text/plain"}
    requests = [
        (f"foreign Host {h}", "GET /api/config", {"headers": {"Host": h}})
        for h in ("evil.example", "evil.example:8050", "127.0.0.1.evil.example", "localhost.attacker", "")
    ]
    requests += [
        (f"foreign Host {h} POST", "POST /api/design", {"headers": {"Host": h}, "json": {}})
        for h in ("evil.example", "rebind.example:80")
    ]
    for path in ("/api/design", "/api/profile", "/api/load", "/api/view", "/api/toml"):
        requests += [
            (f"cross-origin text/plain {path}", f"POST {path}", {"headers": {**origin, **plain}, "content": "{}"}),
            (
                f"cross-origin form {path}",
                f"POST {path}",
                {"headers": {**origin, "Content-Type": "application/x-www-form-urlencoded"}, "content": "a=1"},
            ),
            (f"cross-origin JSON {path}", f"POST {path}", {"headers": origin, "json": {}}),
            (
                f"same-origin JSON without XSRF {path}",
                f"POST {path}",
                {"headers": {"Origin": base.rstrip("/")}, "json": {}},
            ),
        ]
    requests += [
        (
            f"multipart {p}",
            f"POST {p}",
            {"headers": {"Content-Type": "multipart/form-data; boundary=b"}, "content": "--b--\r\n"},
        )
        for p in ("/api/profile", "/api/design")
    ]
    for key in ("light.spectrum", "lens.transmittance", "target.reflectance", "water.type"):
        for value in (str(secret), "/etc/passwd", "/no/such/file.csv", "../../../../etc/hostname", "/dev/zero"):
            requests.append((f"path probe {key}={value}", "POST /api/design", {"json": {"set": {key: value}}}))
    requests += [
        (f"profile probe {p}", "POST /api/profile", {"json": {"path": p}})
        for p in (str(secret), "/etc/passwd", "/nonexistent.toml")
    ]
    requests += [
        (
            "oversized body 50 MB",
            "POST /api/design",
            {
                "headers": {"Content-Type": "application/json"},
                "content": b'{"set": {"x": "' + b"A" * 50_000_000 + b'"}}',
            },
        ),
        (
            "JSON nested 100000 deep",
            "POST /api/design",
            {"headers": {"Content-Type": "application/json"}, "content": "[" * 100_000 + "]" * 100_000},
        ),
    ]
    return requests


def rss_mb(pid: int) -> float:
    process = psutil.Process(pid)
    return sum(p.memory_info().rss for p in [process, *process.children(recursive=True)]) / 2**20


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        secret = Path(tmp) / "secret.csv"
        secret.write_text(f"{SECRET}\n400,1\n")
        explorer = Explorer(str(EXAMPLE), "--host", "0.0.0.0")
        try:
            parts = urlsplit(explorer.url)
            token = dict(parse_qsl(parts.query))["token"]
            base = f"http://127.0.0.1:{parts.port}/"
            succeeded, statuses = [], {}
            with httpx2.Client(base_url=base, timeout=60) as client:
                campaign = hostile(base, secret)
                for name, what, options in campaign:
                    method, path = what.split(" ", 1)
                    for with_token in (False, True):
                        headers = dict(options.get("headers", {}))
                        if with_token and "Host" not in headers:
                            headers["Authorization"] = f"token {token}"
                        answer = client.request(method, path, **{**options, "headers": headers})
                        statuses[answer.status_code] = statuses.get(answer.status_code, 0) + 1
                        # Without the token nothing may succeed; with it, only the refusals of the guard and the
                        # file rules count (a token holder is the user), so a 2xx is a success of the attack.
                        if answer.is_success or SECRET in answer.text or "hunter2" in answer.text:
                            succeeded.append(f"{name} (token: {with_token}) → {answer.status_code}")
            load = load_test(base, token, explorer.process.pid)
        finally:
            explorer.stop()
    print(
        json.dumps(
            {
                "benchmark": "explore_security",
                "hostile_requests": 2 * len(campaign),
                "succeeded": len(succeeded),
                "successes": succeeded,
                "statuses": statuses,
                **load,
            },
            indent=1,
        )
    )


def load_test(base: str, token: str, pid: int) -> dict:
    """CLIENTS threads, each posting designs (a new f-number each time) for LOAD_S seconds."""
    latencies: list[float] = []
    errors = [0]
    lock = threading.Lock()
    stop = time.perf_counter() + LOAD_S

    def client_loop(seed: int) -> None:
        with httpx2.Client(base_url=base, timeout=60, headers={"Authorization": f"token {token}"}) as client:
            i = 0
            while time.perf_counter() < stop:
                body = {"set": {"lens.f_number": 1.4 + 0.01 * ((seed * 97 + i) % 500)}}
                t0 = time.perf_counter()
                answer = client.post("api/design", json=body)
                dt = time.perf_counter() - t0
                with lock:
                    latencies.append(dt)
                    errors[0] += not answer.is_success
                i += 1

    with httpx2.Client(base_url=base, timeout=60, headers={"Authorization": f"token {token}"}) as warm:
        warm.post("api/design", json={})
    before = rss_mb(pid)
    started = time.perf_counter()
    threads = [threading.Thread(target=client_loop, args=(k,)) for k in range(CLIENTS)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    elapsed = time.perf_counter() - started
    ordered = sorted(latencies)
    return {
        "load_clients": CLIENTS,
        "load_requests": len(latencies),
        "load_errors": errors[0],
        "requests_per_s": len(latencies) / elapsed,
        "median_ms": statistics.median(ordered) * 1e3,
        "p99_ms": ordered[int(0.99 * (len(ordered) - 1))] * 1e3,
        "server_rss_before_mb": before,
        "server_rss_after_mb": rss_mb(pid),
    }


if __name__ == "__main__":
    main()
