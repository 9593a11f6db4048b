"""Rig console speed (issue 34): `uwlab console --sim` (a real process on 127.0.0.1, the simulated 2448 × 2048 IMX250
camera) watched by a client that does what the page does — follow the Server-Sent Events and fetch each new frame's
PNG, one at a time, the latest winning — and by headless Chromium (the page itself). Prints one JSON object:

- ``updates_per_s``: frames the client received as PNG per second; ``browser_updates_per_s``: frames the page drew
  per second (its canvas's frame id changing), when Chromium is installed;
- ``server_cpu_cores``: the server process's CPU time over the wall time while watched (1.0 = one core busy);
- ``frame_latency_ms``: from the frame's arrival at the server (``t_grab_s``) to its PNG received (median, p95);
- the sweep: a small plan (``--points``, 12) run by ``uwlab sweep``'s session in this process (``--session-runs``),
  then through the console (``POST /api/runs``) in ``--pairs`` (4) pairs after a warm-up run, one run of each pair
  unwatched and one watched by a page (`Watcher`: the event stream, a PNG for each new frame, the rig on a ``rig``
  event), in the order ABBA ABBA… so that the machine's changing load falls on both alike. Each run's figures are
  the server's own, from its taking the rig to its end (the live view stopped): ``wall_s`` (``elapsed_s``),
  ``cpu_s`` (the console process's CPU seconds), ``run_cpu_s`` (its run thread's: the engine and the drivers) and
  ``serving_cpu_s`` (the difference: the requests and event streams served meanwhile), all in ``sweep_pairs``;
- ``sweep_s``, ``sweep_cpu_s``: median and range of each over the pairs (``session``: of the session's runs);
- ``sweep_slowdown``: watched / unwatched − 1 of the wall times, per pair: median and range (the ≤ 0.10 target);
- ``sweep_cpu_overhead``: what watching added to a pair's serving CPU over its unwatched run's CPU, median and range:
  the load-robust form of the target, since the sweep's own work (a 2448 × 2048 scene rendered and the rig's
  frames) is the same watched or not, while its CPU time, memory-bound, varies by 2–3 times with the machine's load
  (``sweep_cpu_ratio``: watched / unwatched − 1 of the whole CPU, for comparison);
- ``paused_run_server_cpu_cores``: the server's CPU (cores) while a run is paused (nothing changes), without and
  with a watcher, alternating ``--pairs`` times 3 s each, and ``watcher_cores`` their per-pair difference: what a
  watcher costs when there is nothing to tell (the event streams wait for a change instead of polling);
- ``sweep_slowdown_vs_session``: the console's watched runs over the session's (medians) − 1;
- ``load_average``: the 1, 5 and 15 minute load averages before and after.

While a run holds the rig the live view releases the camera, so a watcher costs only the stream's run events (one a
point) and the rig it fetches when the run takes the rig. Targets: ≥ 10 updates/s, ≤ 1 core, ≤ 200 ms; a watched
sweep ≤ 10 % slower. Every wall time depends on the machine's load: on a loaded machine compare
``sweep_cpu_overhead`` and ``watcher_cores``, and `uptime` beside the figures.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import socket
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx2
import psutil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support.console_process import Console  # noqa: E402
from tests.support.plans import write_plan  # noqa: E402
from uwlab.explore.console import STREAM_IDLE_S  # noqa: E402

MAX_FPS = 12
IDLE_S = 3.0
CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


def watch(url: str, seconds: float) -> dict:
    """Follow the stream for ``seconds`` fetching each newest frame; PNGs received and their latencies."""
    latest: dict = {}
    stop = threading.Event()

    def follow() -> None:
        with httpx2.Client(timeout=None) as client, client.stream("GET", url + "api/stream") as stream:
            event = None
            for line in stream.iter_lines():
                if stop.is_set():
                    return
                if line.startswith("event: "):
                    event = line[7:]
                elif line.startswith("data: ") and event == "stats":
                    stats = json.loads(line[6:])
                    latest.update(frame_id=stats["frame_id"], t_grab_s=stats["t_grab_s"])

    threading.Thread(target=follow, daemon=True).start()
    latencies, received, seen = [], 0, -1
    with httpx2.Client(base_url=url, timeout=30) as client:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            frame = dict(latest)
            if not frame or frame["frame_id"] == seen:
                time.sleep(0.002)
                continue
            answer = client.get("api/camera/frame.png", params={"n": frame["frame_id"]})
            answer.raise_for_status()
            latencies.append(time.time() - frame["t_grab_s"])
            received += 1
            seen = frame["frame_id"]
    stop.set()
    return {"received": received, "latencies_s": latencies}


def browser_updates(url: str, seconds: float) -> float | None:
    """Frames per second the page draws in headless Chromium (None without Chromium)."""
    if not Path(CHROMEDRIVER).exists():
        return None
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--window-size=1400,1000"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    try:
        driver.get(url)
        time.sleep(3.0)
        driver.execute_script(
            "window.__drawn = 0; new MutationObserver(() => window.__drawn++)"
            ".observe(document.getElementById('live'), {attributes: true, attributeFilter: ['data-frame-id']});"
        )
        time.sleep(seconds)
        return driver.execute_script("return window.__drawn") / seconds
    finally:
        driver.quit()


def plan(path: Path, points: int) -> Path:
    return write_plan(
        path,
        "console-bench",
        [{"id": "f2", "sensor": "imx250m", "lens": {"focal_length_mm": 30, "f_number": 2.0}, "light_level": 0.35}],
        camera={"pixel_format": "Mono12", "window": [1192, 1000, 64, 48]},
        defaults={
            "kind": "exposure",
            "values": {"start": 50, "stop": 1500, "num": points, "spacing": "log"},
            "frames_per_point": 4,
            "dark": "point",
            "dark_frames": 4,
            "spectrometer": ["target"],
            "spectrometer_integration_ms": 10,
        },
    )


def console_run(client: httpx2.Client, path: Path, out: Path) -> dict[str, float]:
    """A run of the plan through the console, from its taking the rig to its end (the live view stopped): its wall
    time (``elapsed_s``: the engine's work and the rig's opening and closing, as `session_times` counts them), the
    console process's CPU seconds (``cpu_s``), those of the run's own thread (``run_cpu_s``) and the rest
    (``serving_cpu_s``: the requests and event streams served meanwhile); returns once the live view is back."""
    run = client.post("api/runs", json={"plan": str(path), "out": str(out)}).json()["id"]
    while client.get(f"api/runs/{run}").json()["state"] == "running":
        time.sleep(0.25)  # the run's times are the server's: polling seldom adds less to both
    while client.get("api/rig").json()["camera"] is None:
        time.sleep(0.05)
    answer = client.get(f"api/runs/{run}").json()
    if answer["state"] != "done":
        raise RuntimeError(f"the console's run {run} did not finish")
    return {
        "wall_s": answer["elapsed_s"],
        "cpu_s": answer["cpu_s"],
        "run_cpu_s": answer["run_cpu_s"],
        "serving_cpu_s": answer["cpu_s"] - answer["run_cpu_s"],
    }


class Watcher:
    """A page watching the console (as console.js does): it follows the event stream, fetches each new frame's
    PNG (the latest winning) and the rig on a ``rig`` event, and decodes every ``run`` event. Leaving closes the
    stream's socket, as a closed tab does."""

    def __init__(self, url: str):
        self.url, self.events = url, 0
        self._socket: socket.socket | None = None
        self._opened = threading.Event()
        self._thread = threading.Thread(target=self._follow, daemon=True)

    def __enter__(self) -> Watcher:
        self._thread.start()
        self._opened.wait(30)
        return self

    def _follow(self) -> None:
        try:
            with httpx2.Client(base_url=self.url, timeout=30) as client:
                with client.stream("GET", "api/stream", timeout=None) as stream:
                    self._socket = stream.extensions["network_stream"].get_extra_info("socket")
                    self._opened.set()
                    event, seen = None, -1
                    for line in stream.iter_lines():
                        if line.startswith("event: "):
                            event = line[7:]
                        elif line.startswith("data: "):
                            self.events += 1
                            data = json.loads(line[6:])
                            if event == "rig":
                                client.get("api/rig")
                            elif event == "stats" and data["frame_id"] != seen:
                                seen = data["frame_id"]
                                client.get("api/camera/frame.png", params={"n": seen})
        except httpx2.HTTPError:  # left (the socket shut down) or the server stopped
            return
        finally:
            self._opened.set()

    def __exit__(self, *exc) -> None:
        if self._socket is not None:
            with contextlib.suppress(OSError):
                self._socket.shutdown(socket.SHUT_RDWR)
        self._thread.join(timeout=30)
        time.sleep(STREAM_IDLE_S + 0.2)  # the server sees the stream close at its next look


def watcher_idle_cpu(client: httpx2.Client, url: str, server: psutil.Process, folder: Path, pairs: int) -> dict:
    """The console process's CPU (cores: CPU seconds a second) while a run is paused (the live view released, nothing
    changes), without a watcher and with one (`Watcher`), alternating ``pairs`` times for `IDLE_S` each: what a
    watcher costs when there is nothing to tell."""

    def cores() -> float:
        cpu0, t0 = server.cpu_times(), time.monotonic()
        time.sleep(IDLE_S)
        cpu1, t1 = server.cpu_times(), time.monotonic()
        return (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / (t1 - t0)

    path = plan(folder / "long.toml", 200)
    run = client.post("api/runs", json={"plan": str(path), "out": str(folder / "paused")}).json()["id"]
    while client.get(f"api/runs/{run}").json()["points_done"] < 1:
        time.sleep(0.1)
    client.post(f"api/runs/{run}/pause", json={})
    while client.get(f"api/runs/{run}").json()["state"] != "paused":
        time.sleep(0.1)
    time.sleep(1.0)
    cost: dict[str, list[float]] = {"unwatched": [], "watched": []}
    for i in range(pairs):
        for watched in (False, True) if i % 2 == 0 else (True, False):
            if watched:
                with Watcher(url):
                    time.sleep(0.5)  # its first events (the last frame, the rig, the run) answered
                    cost["watched"].append(cores())
            else:
                cost["unwatched"].append(cores())
    client.post(f"api/runs/{run}/abort", json={})
    while client.get("api/rig").json()["camera"] is None:
        time.sleep(0.1)
    return {
        **{name: spread(values) for name, values in cost.items()},
        "watcher_cores": spread([w - u for w, u in zip(cost["watched"], cost["unwatched"], strict=True)]),
    }


def session_times(folder: Path, points: int, repeats: int) -> list[float]:
    """``repeats`` runs of the plan by `uwlab sweep`'s session in this process (after a warm-up run), with no console
    running."""
    from uwlab.experiments.acquisition.plan import load_plan
    from uwlab.experiments.acquisition.session import run_session

    path = plan(folder / "plan.toml", points)
    run_session(load_plan(path), folder / "warm-up", sim=True)
    times = []
    for i in range(repeats):
        t0 = time.perf_counter()
        run_session(load_plan(path), folder / f"session-{i}", sim=True)
        times.append(time.perf_counter() - t0)
    return times


def sweep_pairs(client: httpx2.Client, url: str, folder: Path, points: int, pairs: int) -> list[dict]:
    """``pairs`` pairs of runs of the plan through the console, one unwatched and one watched (`Watcher`), in the
    order ABBA ABBA… (unwatched first in even pairs) after a warm-up run, so that a change of the machine's load
    falls on both alike; each pair's `console_run` times."""
    path = plan(folder / "plan.toml", points)
    console_run(client, path, folder / "warm-up")
    out = []
    for i in range(pairs):
        pair: dict[str, dict] = {}
        for watched in (False, True) if i % 2 == 0 else (True, False):
            name = "watched" if watched else "unwatched"
            if watched:
                with Watcher(url):
                    pair[name] = console_run(client, path, folder / f"{name}-{i}")
            else:
                pair[name] = console_run(client, path, folder / f"{name}-{i}")
        out.append(pair)
    return out


def spread(values: list[float]) -> dict[str, float]:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def slowdown(pairs: list[dict], key: str) -> dict[str, float]:
    """Watched / unwatched − 1 of each pair's ``key`` (wall_s or cpu_s): median and range."""
    return spread([p["watched"][key] / p["unwatched"][key] - 1.0 for p in pairs])


def serving_overhead(pairs: list[dict]) -> dict[str, float]:
    """What watching added to each pair's serving CPU, over the unwatched run's CPU: median and range."""
    return spread(
        [(p["watched"]["serving_cpu_s"] - p["unwatched"]["serving_cpu_s"]) / p["unwatched"]["cpu_s"] for p in pairs]
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter
    )
    parser.add_argument("--watch-s", type=float, default=15.0, help="seconds the live view is watched (15)")
    parser.add_argument("--points", type=int, default=12, help="exposures in the plan (12)")
    parser.add_argument("--pairs", type=int, default=4, help="pairs of console runs, unwatched and watched (4)")
    parser.add_argument("--session-runs", type=int, default=2, help="runs by `uwlab sweep`'s session (2)")
    args = parser.parse_args()
    load = {"before": list(psutil.getloadavg())}
    with tempfile.TemporaryDirectory() as folder:
        session = session_times(Path(folder), args.points, args.session_runs)
    console = Console("--sim", "--max-fps", str(MAX_FPS))
    try:
        server = psutil.Process(console.process.pid)
        time.sleep(3.0)
        cpu0, t0 = server.cpu_times(), time.monotonic()
        watched = watch(console.url, args.watch_s)
        cpu1, t1 = server.cpu_times(), time.monotonic()
        cores = (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / (t1 - t0)
        in_browser = browser_updates(console.url, args.watch_s / 2)
        with tempfile.TemporaryDirectory() as folder, httpx2.Client(base_url=console.url, timeout=60) as client:
            while not client.post("api/control", json={}).json()["controlling"]:  # the browser's page just closed
                time.sleep(0.5)
            pairs = sweep_pairs(client, console.url, Path(folder), args.points, args.pairs)
            idle = watcher_idle_cpu(client, console.url, server, Path(folder), args.pairs)
    finally:
        console.stop()
    load["after"] = list(psutil.getloadavg())
    latencies = sorted(watched["latencies_s"])
    watched_wall = [p["watched"]["wall_s"] for p in pairs]
    print(
        json.dumps(
            {
                "camera_px": [2448, 2048],
                "max_fps": MAX_FPS,
                "updates_per_s": watched["received"] / args.watch_s,
                "browser_updates_per_s": in_browser,
                "server_cpu_cores": cores,
                "frame_latency_ms": {
                    "median": statistics.median(latencies) * 1e3,
                    "p95": latencies[int(0.95 * (len(latencies) - 1))] * 1e3,
                },
                "points": args.points,
                "sweep_pairs": pairs,
                "sweep_s": {
                    "session": spread(session),
                    "console_unwatched": spread([p["unwatched"]["wall_s"] for p in pairs]),
                    "console_watched": spread(watched_wall),
                },
                "sweep_cpu_s": {
                    f"console_{name}_{key}": spread([p[name][key] for p in pairs])
                    for name in ("unwatched", "watched")
                    for key in ("cpu_s", "run_cpu_s", "serving_cpu_s")
                },
                "sweep_slowdown": slowdown(pairs, "wall_s"),
                "sweep_cpu_ratio": slowdown(pairs, "cpu_s"),
                "sweep_cpu_overhead": serving_overhead(pairs),
                "paused_run_server_cpu_cores": idle,
                "sweep_slowdown_vs_session": statistics.median(watched_wall) / statistics.median(session) - 1.0,
                "load_average": load,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
