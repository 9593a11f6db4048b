"""`uwlab explore` as a real process on 127.0.0.1 for the tests: started with ``--json --port 0 --no-browser``,
its URL read from the first line, stopped with Ctrl-C (SIGINT); and the hostile-request campaign run against it
(planted secret files and the probes naming them, raw requests, held connections), shared by
tests/integration/test_explore_hostile.py and benchmarks/hostile_requests.py."""

from __future__ import annotations

import json
import select
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import urlsplit

START_TIMEOUT_S = 120


class Explorer:
    """``uwlab VERB`` (the explorer; `tests.support.console_process.Console` the console) as a real process."""

    VERB = "explore"
    STOP_TIMEOUT_S = 30

    def __init__(self, *args: str):
        self.process = subprocess.Popen(
            [sys.executable, "-m", "uwlab.cli.main", self.VERB, "--no-browser", "--json", "--port", "0", *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        ready, _, _ = select.select([self.process.stdout], [], [], START_TIMEOUT_S)
        line = self.process.stdout.readline() if ready else ""
        if not line:
            _, err = self.stop()
            raise RuntimeError(f"uwlab {self.VERB} did not start: {err}")
        self.url = json.loads(line)["url"]

    def stop(self) -> tuple[int, str]:
        """Ctrl-C; returns (exit code, stderr)."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=self.STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=30)
        err = self.process.stderr.read()
        self.process.stdout.close()
        self.process.stderr.close()
        return self.process.returncode, err


# ---- the hostile-request campaign (tests/integration/test_explore_hostile.py, benchmarks/hostile_requests.py) --

SECRET = "password=hunter2"
FILE_KEYS = ("light.spectrum", "lens.transmittance", "target.reflectance", "water.type", "sensor.profile")


def plant_secrets(folder: Path) -> Path:
    """Files outside the explorer's roots that would be quoted if read: a CSV with every spectral column a design
    file may have, each cell `SECRET`, and a sensor profile TOML whose values are `SECRET`. Returns ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    columns = ("wavelength_nm", "relative", "reflectance", "transmittance", "a_per_m", "b_per_m", "qe")
    (folder / "secret.csv").write_text(",".join(columns) + "\n400," + ",".join([SECRET] * (len(columns) - 1)) + "\n")
    (folder / "secret.toml").write_text(f'name = "{SECRET}"\nbit_depth = "{SECRET}"\nqe_csv = "secret.csv"\n')
    return folder


def secret_names(folder: Path) -> list[str]:
    """Ways of naming the planted files (and a missing one beside them): absolute, with ``.``/``..``, a trailing
    separator or ``/.``, without the ``.toml`` a sensor profile may omit, relative to the served folder."""
    csv, toml = folder / "secret.csv", folder / "secret.toml"
    return [
        str(csv),
        str(toml),
        str(folder / "secret"),
        f"{toml}/",
        f"{toml}/.",
        f"{folder}/./secret.csv",
        f"{folder}/none/../secret.csv",
        "../" * 12 + str(csv).lstrip("/"),
        "../" * 12 + str(folder / "secret").lstrip("/"),
        str(folder / "missing.csv"),
        "x" * 300 + ".csv",
    ]


def file_probes(folder: Path) -> list[tuple[str, str, dict]]:
    """(name, API path, JSON body) naming each of `secret_names` through every file-valued key and every endpoint
    that takes a design (as a ``set`` value, a ``text`` value, an uploaded TOML, a sweep grid's list or text) and
    ``/api/profile``."""
    probes = []
    for value in secret_names(folder):
        probes.append((f"profile {value}", "/api/profile", {"path": value}))
        for key in FILE_KEYS:
            section, _, name = key.partition(".")
            toml = f"[{section}]\n{name} = {json.dumps(value)}\n"
            for path, body in (
                ("/api/design", {"set": {key: value}}),
                ("/api/view", {"text": {key: json.dumps(value)}}),
                ("/api/toml", {"set": {key: value}}),
                ("/api/load", {"toml": toml, "name": "upload.toml"}),
                ("/api/sweep", {"grid": {key: [value]}, "output": "snr_db"}),
                ("/api/sweep", {"grid": {key: f"{value},{value}"}, "output": "snr_db"}),
                ("/api/solve", {"set": {key: value}, "free": ["lens.f_number=1.4:8"], "objectives": []}),
            ):
                probes.append((f"{path} {key}={value[:60]}", path, body))
    return probes


def raw_request(port: int, request: bytes, timeout_s: float = 60) -> tuple[int, dict[str, str], bytes]:
    """Send ``request`` as is to 127.0.0.1:port and read the answer to its end: (status, headers, body); status 0
    when the server closed without answering."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout_s) as sock:
        sock.sendall(request)
        data = b""
        while chunk := sock.recv(65536):
            data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    if not lines[0].startswith("HTTP/"):
        return 0, {}, data
    headers = {}
    for line in lines[1:]:
        name, _, value = line.partition(":")
        headers.setdefault(name.strip().lower(), value.strip())
    return int(lines[0].split()[1]), headers, body


def hostile_requests(port: int, token: str | None) -> list[tuple[str, bytes]]:
    """(name, raw HTTP/1.1 request) of requests meant to make the server fail, redirect off-site or set a cookie
    it did not make: odd paths with the token, malformed Host headers, forged tokens, long and odd names."""
    q = f"token={token}" if token else "token=x"
    host = f"127.0.0.1:{port}"

    def get(target: str, host_header: str = host, extra: str = "") -> bytes:
        return f"GET {target} HTTP/1.1\r\nHost: {host_header}\r\n{extra}Connection: close\r\n\r\n".encode("latin-1")

    def post(path: str, body: bytes, extra: str = "") -> bytes:
        auth = f"Authorization: token {token}\r\n" if token else ""
        return (
            f"POST {path} HTTP/1.1\r\nHost: {host}\r\n{auth}{extra}Content-Type: application/json\r\n"
            f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n"
        ).encode("latin-1") + body

    requests = [
        ("non-Latin-1 path", get(f"/%E2%82%AC?{q}")),
        ("non-UTF-8 path", get(f"/%FF%FE?{q}")),
        ("network-path redirect", get(f"//evil.example/?{q}")),
        ("network-path redirect, three slashes", get(f"///evil.example/x?{q}")),
        ("backslash redirect", get(f"/\\evil.example/?{q}")),
        ("encoded slashes redirect", get(f"/%2F%2Fevil.example/?{q}")),
        ("cookie injection in the token", get("/?token=abcdefgh%3B%20Domain%3Devil.example")),
        ("cookie injection beside the token", get(f"/?{q}&token=x%3B%20Domain%3Devil")),
        ("non-Latin-1 query", get(f"/?{q}&x=%E2%82%AC")),
        ("long path", get("/" + "a" * 8000 + f"?{q}")),
        ("odd cookie", get(f"/?{q}", extra='Cookie: uwlab_token="a;b"; _xsrf=\x80\x81\r\n')),
        ("odd authorization", get("/api/config", extra="Authorization: token \xe9\xe9\xe9\r\n")),
    ]
    requests += [
        (f"Host {h!r}", get("/api/config", h))
        for h in (
            f"127.0.0.1:{port}.evil.com",
            f"localhost:{port}@evil.com",
            f"[localhost]:{port}",
            "localhost:",
            f"127.0.0.1:{port}:{port}",
            "[::1",
            "\xe9vil.example",
            "evil.example",
            "",
        )
    ]
    requests.append(("two Host headers", get("/api/config", extra="Host: evil.example\r\n")))
    for path, body in (
        ("/api/load", json.dumps({"toml": "x = 1", "name": "n" * 300}).encode()),
        (
            "/api/load",
            json.dumps({"toml": f'[lens]\ntransmittance = "{"t" * 5000}.csv"\nname = "{"n" * 5000}"'}).encode(),
        ),
        ("/api/load", json.dumps({"toml": '[sensor]\nprofile = "' + "p" * 300 + '"'}).encode()),
        ("/api/load", json.dumps({"toml": "[light]\nspectrum = 1e400"}).encode()),
        ("/api/design", json.dumps({"set": {"sensor.profile": "\u20ac" * 300}}).encode()),
        ("/api/design", json.dumps({"set": {"light.spectrum": "a\u0000b.csv"}}).encode()),
        ("/api/design", json.dumps({"text": {"lens.f_number": "1e999"}}).encode()),
        ("/api/design", b'{"set": {"lens.f_number": NaN}}'),
        ("/api/design", b"\xff\xfe{}"),
        ("/api/sweep", json.dumps({"grid": {"lens.f_number": "1:2:0"}, "output": "snr_db"}).encode()),
        ("/api/sweep", json.dumps({"grid": {"lens.f_number": "1:1e12:1e-12"}, "output": "snr_db"}).encode()),
        ("/api/profile", json.dumps({"path": "p" * 5000}).encode()),
        ("/api/profile", json.dumps({"path": "/dev/zero"}).encode()),
        ("/api/nothing", b"{}"),
    ):
        requests.append((f"POST {path} {body[:40]!r}", post(path, body)))
    return requests


def offsite(location: str | None) -> bool:
    """True when a redirect's Location leaves the server: a scheme or a network-path reference (``//``, and
    ``/\\``, which browsers read the same way)."""
    if not location:
        return False
    return bool(urlsplit(location).scheme or urlsplit(location).netloc) or location.replace("\\", "/").startswith("//")


def held_connections(port: int, count: int, limit_s: float, probe) -> dict:
    """Open ``count`` connections to 127.0.0.1:port that hold the server: a third send nothing, a third send
    headers a byte a second, a third send whole headers and then their body a byte a second. Call ``probe()`` (a
    normal request; returns its latency in s or None when it failed) about every second until every held
    connection is closed by the server or ``limit_s`` has passed. Returns {"held", "closed", "worst_close_s",
    "probes", "probes_failed", "worst_probe_s"}."""
    head = f"GET /api/config HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nX-Slow: "
    body_head = (
        f"POST /api/design HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json\r\n"
        "Content-Length: 100000\r\n\r\n{"
    )
    started = time.monotonic()
    held: dict[socket.socket, bytes] = {}
    closed_at: dict[socket.socket, float] = {}
    for i in range(count):
        sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        sock.setblocking(False)
        kind = i % 3
        if kind:
            sock.sendall((head if kind == 1 else body_head).encode())
        held[sock] = b"" if kind == 0 else b"a" if kind == 1 else b" "
    latencies: list[float | None] = []
    try:
        while len(closed_at) < count and time.monotonic() - started < limit_s:
            open_now = [s for s in held if s not in closed_at]
            readable, _, _ = select.select(open_now, [], [], 1.0)
            for sock in open_now:
                gone = False
                if sock in readable:
                    try:
                        gone = sock.recv(65536) == b""
                    except OSError:
                        gone = True
                if not gone and held[sock]:
                    try:
                        sock.send(held[sock] if sock not in readable else b"")
                    except OSError:
                        gone = True
                if gone:
                    closed_at[sock] = time.monotonic() - started
            latencies.append(probe())
    finally:
        for sock in held:
            sock.close()
    answered = [t for t in latencies if t is not None]
    return {
        "held": count,
        "closed": len(closed_at),
        "worst_close_s": max(closed_at.values(), default=None),
        "probes": len(latencies),
        "probes_failed": len(latencies) - len(answered),
        "worst_probe_s": max(answered, default=None),
    }
