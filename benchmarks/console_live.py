"""Rig console speed (issue 34): `uwlab console --sim` (a real process on 127.0.0.1, the simulated 2448 × 2048 IMX250
camera) watched by a client that does what the page does — follow the Server-Sent Events and fetch each new frame's
PNG, one at a time, the latest winning — and by headless Chromium (the page itself). Prints one JSON object:

- ``updates_per_s``: frames the client received as PNG per second; ``browser_updates_per_s``: frames the page drew
  per second (its canvas's frame id changing), when Chromium is installed;
- ``server_cpu_cores``: the server process's CPU time over the wall time while watched (1.0 = one core busy);
- ``frame_latency_ms``: from the frame's arrival at the server (``t_grab_s``) to its PNG received (median, p95);
- ``sweep_s``: a small plan (12 points) run by ``uwlab sweep``'s session in this process, and through the console
  (``POST /api/runs``) unwatched and with a watcher on the event stream (best of two each); ``sweep_slowdown``:
  watched / unwatched − 1 (target ≤ 0.10), ``sweep_slowdown_vs_session``: watched / session − 1. While a run holds
  the rig the live view releases the camera, so a watcher costs only the stream's run events.

Targets: ≥ 10 updates/s, ≤ 1 core, ≤ 200 ms. The machine's load changes every number: run it on a quiet machine.
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import psutil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support.console_process import Console  # noqa: E402
from tests.support.plans import write_plan  # noqa: E402

WATCH_S = 15.0
CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


def watch(url: str, seconds: float) -> dict:
    """Follow the stream for ``seconds`` fetching each newest frame; PNGs received and their latencies."""
    latest: dict = {}
    stop = threading.Event()

    def follow() -> None:
        with httpx.Client(timeout=None) as client, client.stream("GET", url + "api/stream") as stream:
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
    with httpx.Client(base_url=url, timeout=30) as client:
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


def plan(path: Path) -> Path:
    return write_plan(
        path,
        "console-bench",
        [{"id": "f2", "sensor": "imx250m", "lens": {"focal_length_mm": 30, "f_number": 2.0}, "light_level": 0.35}],
        camera={"pixel_format": "Mono12", "window": [1192, 1000, 64, 48]},
        defaults={
            "kind": "exposure",
            "values": {"start": 50, "stop": 1500, "num": 12, "spacing": "log"},
            "frames_per_point": 4,
            "dark": "point",
            "dark_frames": 4,
            "spectrometer": ["target"],
            "spectrometer_integration_ms": 10,
        },
    )


def console_run(client: httpx.Client, path: Path, out: Path) -> float:
    """A run of the plan through the console: its time from taking the rig to its end (``elapsed_s``, the engine's
    work and the rig's opening and closing, as `session_time` counts them); returns once the live view is back."""
    run = client.post("api/runs", json={"plan": str(path), "out": str(out)}).json()["id"]
    while (answer := client.get(f"api/runs/{run}").json())["state"] == "running":
        time.sleep(0.05)
    if answer["state"] != "done":
        raise RuntimeError(f"the console's run {run} did not finish")
    while client.get("api/rig").json()["camera"] is None:
        time.sleep(0.05)
    return answer["elapsed_s"]


def session_time(folder: Path, repeats: int = 2) -> float:
    """The best of ``repeats`` runs of the plan by `uwlab sweep`'s session in this process (after a warm-up run),
    with no console running."""
    from uwlab.experiments.acquisition.plan import load_plan
    from uwlab.experiments.acquisition.session import run_session

    path = plan(folder / "plan.toml")
    run_session(load_plan(path), folder / "warm-up", sim=True)
    times = []
    for i in range(repeats):
        t0 = time.perf_counter()
        run_session(load_plan(path), folder / f"session-{i}", sim=True)
        times.append(time.perf_counter() - t0)
    return min(times)


def sweep_times(url: str, folder: Path, repeats: int = 2) -> dict:
    """The best of ``repeats`` runs of the plan through the console unwatched, and with a watcher on its event
    stream."""
    path = plan(folder / "plan.toml")
    times: dict[str, list[float]] = {"console_unwatched": [], "console_watched": []}
    with httpx.Client(base_url=url, timeout=60) as client:
        while not client.post("api/control", json={}).json()["controlling"]:  # the browser's page just closed
            time.sleep(0.5)
        for i in range(repeats):
            times["console_unwatched"].append(console_run(client, path, folder / f"unwatched-{i}"))
        stop = threading.Event()

        def follow() -> None:  # a watcher on the event stream, as the page is
            try:
                with httpx.Client(timeout=None) as watcher, watcher.stream("GET", url + "api/stream") as stream:
                    for _ in stream.iter_lines():
                        if stop.is_set():
                            return
            except httpx.HTTPError:  # the server stopped
                return

        threading.Thread(target=follow, daemon=True).start()
        for i in range(repeats):
            times["console_watched"].append(console_run(client, path, folder / f"watched-{i}"))
        stop.set()
    return {name: min(values) for name, values in times.items()}


def main() -> None:
    with tempfile.TemporaryDirectory() as folder:
        session = session_time(Path(folder))
    console = Console("--sim", "--max-fps", "12")
    try:
        server = psutil.Process(console.process.pid)
        time.sleep(3.0)
        cpu0, t0 = server.cpu_times(), time.monotonic()
        watched = watch(console.url, WATCH_S)
        cpu1, t1 = server.cpu_times(), time.monotonic()
        cores = (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / (t1 - t0)
        in_browser = browser_updates(console.url, WATCH_S / 2)
        with tempfile.TemporaryDirectory() as folder:
            sweep = sweep_times(console.url, Path(folder))
    finally:
        console.stop()
    latencies = sorted(watched["latencies_s"])
    print(
        json.dumps(
            {
                "camera_px": [2448, 2048],
                "max_fps": 12,
                "updates_per_s": watched["received"] / WATCH_S,
                "browser_updates_per_s": in_browser,
                "server_cpu_cores": cores,
                "frame_latency_ms": {
                    "median": statistics.median(latencies) * 1e3,
                    "p95": latencies[int(0.95 * (len(latencies) - 1))] * 1e3,
                },
                "sweep_s": {"session": session, **sweep},
                "sweep_slowdown": sweep["console_watched"] / sweep["console_unwatched"] - 1.0,
                "sweep_slowdown_vs_session": sweep["console_watched"] / session - 1.0,
                "load_average": list(psutil.getloadavg()),
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
