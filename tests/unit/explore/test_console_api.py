"""The rig console's JSON API on the simulated rig (uwlab/explore/console.py, console_rig.py): read-backs, frames,
statistics against the frame's own pixels, bad settings as one line, runs paused and resumed giving the dataset
`uwlab sweep --sim` gives, watchers refused, and the explorer's hostile requests refused by the console too."""

from __future__ import annotations

import io
import json
import time

import numpy as np
import pytest
from PIL import Image
from starlette.testclient import TestClient

from tests.support.paths import SIM_TANK
from tests.support.plans import write_plan
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.session import run_session
from uwlab.experiments.dataset import Dataset
from uwlab.explore.console import create_console
from uwlab.explore.console_rig import Live, Runs, Source
from uwlab.explore.security import Access

LOCAL = "http://127.0.0.1:8060"
WAIT_S = 120
POSTS = [
    ("/api/camera", {"exposure_us": 300}),
    ("/api/view", {"roi": [10, 10, 50, 50]}),
    ("/api/focus/reset", {}),
    ("/api/lights/light", {"on": False}),
    ("/api/runs", {"plan": "x.toml"}),
    ("/api/runs/none/pause", {}),
]
# Values of the dataset that a watcher's presence could change: every measured column (times excluded).
TIMING = ("t_start_ns", "t_end_ns", "readback_t_start_ns", "readback_t_end_ns")


@pytest.fixture(scope="module")
def console():
    live = Live(Source(SIM_TANK, sim=True), max_fps=20)
    runs = Runs(live, sim=True)
    live.start()
    try:
        yield live, runs
    finally:
        runs.close()
        live.close()


@pytest.fixture(scope="module")
def app(console):
    return create_console(*console)


@pytest.fixture
def client(app):
    with TestClient(app, base_url=LOCAL) as c:
        yield c
        c.post("/api/control", json={"release": True})


def wait_for(condition, message):
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(message)


def next_stats(c, after: int | None = None) -> dict:
    """Stats of a frame newer than ``after`` (any frame when None)."""

    def newer():
        answer = c.get("/api/camera/stats")
        return answer.status_code == 200 and (after is None or answer.json()["frame_id"] > after) and answer.json()

    return wait_for(newer, "no new frame")


def test_rig_reads_back_the_camera_lights_and_spectrometer(client):
    rig = client.get("/api/rig").json()
    camera = rig["camera"]
    assert camera["model"] == "SimCam-IMX250M" and (camera["width"], camera["height"]) == (2448, 2048)
    assert {"exposure_us", "gain_db", "pixel_format"} <= set(camera)
    assert set(rig["lights"]) == {"light"} and {"on", "level"} <= set(rig["lights"]["light"])
    assert rig["spectrometer"]["model"].startswith("UWLAB,SIM-SPECTROMETER")


def test_a_setting_is_answered_by_its_read_back_and_the_frames_follow(client):
    off = client.post("/api/lights/light", json={"on": False}).json()
    assert off["on"] is False
    client.post("/api/camera", json={"exposure_us": 200.0})
    dark = wait_for(lambda: (s := next_stats(client))["exposure_us"] == 200.0 and s, "no frame")["mean_dn"]
    light = client.post("/api/lights/light", json={"on": True, "level": 1.0}).json()
    assert light["on"] is True and light["level"] == pytest.approx(1.0)
    means = {}
    for exposure in (200.0, 400.0):
        readback = client.post("/api/camera", json={"exposure_us": exposure})
        assert readback.status_code == 200 and readback.json()["exposure_us"] == pytest.approx(exposure)

        def lit(e=exposure):
            stats = next_stats(client)
            return stats["exposure_us"] == e and stats["mean_dn"] > dark + 100 and stats

        means[exposure] = wait_for(lit, "no lit frame")["mean_dn"]
    # Twice the exposure, twice the signal above the dark level (the sim's linear sensor, well below clip).
    assert (means[400.0] - dark) / (means[200.0] - dark) == pytest.approx(2.0, rel=0.05)


def test_the_saturated_fraction_and_the_clipping_overlay_are_the_frames_own(client):
    client.post("/api/lights/light", json={"on": True, "level": 1.0})
    client.post("/api/camera", json={"exposure_us": 3000.0})
    stats = wait_for(lambda: (s := next_stats(client))["exposure_us"] == 3000.0 and s, "no frame")
    assert stats["saturated_fraction"] > 0.01
    full = client.get("/api/camera/frame.png", params={"scale": 1, "clip": 1})
    image = np.asarray(Image.open(io.BytesIO(full.content)).convert("RGB"))
    assert image.shape[:2] == (2048, 2448)
    red = np.all(image == (255, 0, 40), axis=2).mean()
    # The PNG is the frame the stats were computed from or a later one at the same settings.
    assert red == pytest.approx(stats["saturated_fraction"], rel=0.05)
    small = np.asarray(Image.open(io.BytesIO(client.get("/api/camera/frame.png").content)).convert("RGB"))
    assert max(small.shape[:2]) <= 800
    client.post("/api/lights/light", json={"on": False})


def test_the_roi_statistics_follow_the_roi(client):
    answer = client.post("/api/view", json={"roi": [100, 200, 64, 32]})
    assert answer.status_code == 200
    stats = wait_for(lambda: (s := next_stats(client))["roi"]["x"] == 100 and s, "ROI not applied")
    roi = stats["roi"]
    assert (roi["y"], roi["w"], roi["h"]) == (200, 64, 32)
    assert roi["snr"] == pytest.approx(roi["mean_dn"] / np.sqrt(roi["variance_dn2"]))


@pytest.mark.parametrize(
    "body, key",
    [
        ({"exposure_us": 1e9}, "exposure_us"),  # plausible, beyond the camera's own limit
        ({"exposure_us": -5}, "exposure_us"),
        ({"gain_db": "high"}, "gain_db"),
        ({"pixel_format": "Mono99"}, "pixel_format"),
        ({"roi": [0, 0, 5000, 10]}, "roi"),
        ({"focus": 3}, "focus"),
    ],
)
def test_a_setting_outside_the_limits_is_one_line(client, body, key):
    answer = client.post("/api/camera", json=body)
    assert answer.status_code == 422
    error = answer.json()
    assert error["key"] == key and "\n" not in error["error"]


def test_the_stream_pushes_stats_and_rig_events(client):
    with client.stream("GET", "/api/stream", params={"limit": 3}) as stream:
        text = "".join(stream.iter_text())
    events = [block for block in text.split("\n\n") if block.startswith("event:")]
    names = [block.splitlines()[0].split(": ")[1] for block in events]
    assert "stats" in names
    stats = json.loads(events[names.index("stats")].splitlines()[1][len("data: ") :])
    assert {"mean_dn", "saturated_fraction", "sharpness", "fps"} <= set(stats)


def test_the_model_focus_setting_is_port_traces(client):
    from uwlab.model.port_field import trace_design
    from uwlab.sim.scene import RigScene

    focus = client.get("/api/focus").json()
    expected = trace_design(RigScene.from_toml(SIM_TANK).design)["focus"]
    assert focus["model"]["setting_m"] == pytest.approx(expected["setting_m"])
    assert focus["model"]["image_distance_m"] < focus["model"]["target_distance_m"]  # a flat port brings it closer


def test_a_watcher_cannot_change_anything(client, app):
    client.get("/")  # the first session takes control
    with TestClient(app, base_url=LOCAL) as watcher:
        watcher.get("/")
        assert watcher.get("/api/rig").json()["control"]["controlling"] is False
        for path, body in POSTS:
            answer = watcher.post(path, json=body)
            assert answer.status_code == 403 and "watches" in answer.json()["error"], path
        assert watcher.post("/api/control", json={}).json()["controlling"] is False


def test_bad_runs_are_one_line(client, tmp_path):
    answer = client.post("/api/runs", json={"plan": str(tmp_path / "missing.toml"), "out": str(tmp_path / "d")})
    assert answer.status_code == 422 and "\n" not in answer.json()["error"]
    assert client.post("/api/runs/nosuchrun/pause", json={}).status_code == 404


def small_plan(path, light_level: float = 0.35):
    return write_plan(
        path,
        "console-run",
        [{"id": "imx250-f2", "sensor": "imx250m", "lens": {"focal_length_mm": 30, "f_number": 2.0}}],
        camera={"pixel_format": "Mono12", "window": [1192, 1000, 16, 12]},
        defaults={
            "kind": "exposure",
            "values": {"start": 50, "stop": 800, "num": 5, "spacing": "log"},
            "frames_per_point": 2,
            "dark": "point",
            "dark_frames": 2,
            "light_level": light_level,
        },
    )


def test_a_run_paused_and_resumed_is_the_dataset_of_uwlab_sweep(client, tmp_path):
    plan = small_plan(tmp_path / "plan.toml")
    started = client.post("/api/runs", json={"plan": str(plan), "out": str(tmp_path / "console")})
    assert started.status_code == 200
    run_id = started.json()["id"]
    client.post(f"/api/runs/{run_id}/pause", json={})
    paused = wait_for(lambda: (r := client.get(f"/api/runs/{run_id}").json())["state"] == "paused" and r, "no pause")
    assert paused["lights_safe_state"] == {"light": True} and 0 < paused["points_done"] < 5
    assert client.get(f"/api/runs/{run_id}").json()["points_done"] == paused["points_done"]  # it waits
    assert client.post(f"/api/runs/{run_id}/resume", json={}).status_code == 200
    done = wait_for(lambda: (r := client.get(f"/api/runs/{run_id}").json())["state"] == "done" and r, "not done")
    assert done["points_done"] == done["points_total"] == 5 and len(done["points"]) == 5
    again = client.post(f"/api/runs/{run_id}/pause", json={})
    assert again.status_code == 422 and "done" in again.json()["error"]
    wait_for(lambda: client.get("/api/rig").json()["camera"] is not None, "the live view did not come back")
    assert paused["cpu_s"] is None  # known once the run has ended
    ended = client.get(f"/api/runs/{run_id}").json()
    assert 0 < ended["run_cpu_s"] <= ended["cpu_s"]  # the run's thread is one of the console's

    reference = run_session(load_plan(plan), tmp_path / "sweep", sim=True)  # what `uwlab sweep --sim` runs
    ours, theirs = Dataset.open(tmp_path / "console").points(), Dataset.open(reference).points()
    assert len(ours) == len(theirs) == 5
    measured = [c for c in theirs.columns if c not in TIMING]
    for (_, a), (_, b) in zip(ours[measured].iterrows(), theirs[measured].iterrows(), strict=True):
        assert _same(a.to_dict(), b.to_dict())


def test_a_run_answers_the_models_band_and_its_points_fall_inside(client, app, tmp_path):
    plan = small_plan(tmp_path / "plan.toml", light_level=1.0)
    run_id = client.post("/api/runs", json={"plan": str(plan), "out": str(tmp_path / "banded")}).json()["id"]
    done = wait_for(lambda: (r := client.get(f"/api/runs/{run_id}").json())["state"] == "done" and r, "not done")
    assert done["prediction_source"] == "design"
    with TestClient(app, base_url=LOCAL) as watcher:  # a watcher reads it too
        prediction = watcher.get(f"/api/runs/{run_id}/prediction").json()
    assert prediction["source"] == "design" and prediction["band_percent"] == [2.5, 97.5]
    (band,) = prediction["configurations"]
    assert band["sweep_id"] == "imx250-f2" and len(band["exposure_us"]) == len(band["lo"]) == len(band["hi"]) > 5
    # The simulated points (the simulator's truth, which the prediction never sees) fall inside the band; the band
    # is linear in log-log between its exposures (the response is a power of the exposure).
    x = np.log(band["exposure_us"])
    for point in done["points"]:
        lo, hi = (np.exp(np.interp(np.log(point["exposure_us"]), x, np.log(band[k]))) for k in ("lo", "hi"))
        assert lo <= point["signal_dn"] <= hi, point
    assert client.get("/api/runs/nosuchrun/prediction").status_code == 404
    # A sweep with the light dimmed is not predicted (its output is measured, not modelled), and says so.
    dimmed = client.post(
        "/api/runs", json={"plan": str(small_plan(tmp_path / "dimmed.toml")), "out": str(tmp_path / "dimmed")}
    ).json()["id"]
    prediction = client.get(f"/api/runs/{dimmed}/prediction").json()
    assert prediction["configurations"] == [] and "light level 0.35" in prediction["skipped"]["imx250-f2"]
    wait_for(lambda: client.get(f"/api/runs/{dimmed}").json()["state"] == "done", "not done")
    wait_for(lambda: client.get("/api/rig").json()["camera"] is not None, "the live view did not come back")


def test_a_fit_that_is_not_of_the_plan_is_refused_before_the_run(client, tmp_path):
    import pandas as pd

    plan = small_plan(tmp_path / "plan.toml", light_level=1.0)
    other = tmp_path / "other-fit"  # a fit directory of another lens (its files as `uwlab fit` writes them)
    other.mkdir()
    (other / "summary.json").write_text(json.dumps({"model": "paper", "parameters": {}}))
    pd.DataFrame(
        {"sensor_profile": ["imx250m"], "focal_length_mm": [12.0], "f_number": [4.0], "saturated": [False]}
    ).to_parquet(other / "predictions.parquet")
    pd.DataFrame({"light_efficiency": [0.8, 0.9]}).to_parquet(other / "samples.parquet")
    for fit, words in (
        (str(tmp_path / "missing"), "not a directory"),
        (str(other), "has no configuration"),
        (3, "fit"),
    ):
        answer = client.post("/api/runs", json={"plan": str(plan), "out": str(tmp_path / "d"), "fit": fit})
        error = answer.json()["error"]
        assert answer.status_code == 422 and words in error and "\n" not in error and answer.json()["key"] == "fit"
    assert not (tmp_path / "d").exists()  # refused before the dataset was made


def _same(a: dict, b: dict) -> bool:
    """Every value equal (arrays element by element, NaN equal to NaN)."""

    def equal(x, y) -> bool:
        if isinstance(x, list | np.ndarray) or isinstance(y, list | np.ndarray):
            return list(np.asarray(x).ravel()) == list(np.asarray(y).ravel())
        return bool(x == y) or (isinstance(x, float) and isinstance(y, float) and np.isnan(x) and np.isnan(y))

    different = {k: (a[k], b[k]) for k in a if not equal(a[k], b[k])}
    assert not different, different
    return True


# ---- the explorer's hostile requests, against the console -----------------------------------------------------


@pytest.mark.parametrize("host", ["evil.example", "evil.example:8060", "127.0.0.1.evil.example", "", "0.0.0.0"])
def test_a_foreign_host_is_refused(client, host):
    for method, path in (("GET", "/"), ("GET", "/api/rig"), ("GET", "/api/camera/frame.png"), ("POST", "/api/camera")):
        answer = client.request(method, path, headers={"Host": host}, json={} if method == "POST" else None)
        assert answer.status_code == 403 and "host not allowed" in answer.json()["error"]


@pytest.mark.parametrize("origin", ["http://evil.example", "null", "http://127.0.0.1:9999"])
def test_cross_origin_and_unsigned_browser_posts_never_act(client, origin):
    client.get("/")
    before = client.get("/api/rig").json()["camera"]["exposure_us"]
    for path, body in POSTS:
        cross = client.post(path, json=body, headers={"Origin": origin, "X-XSRF-Token": client.cookies.get("_xsrf")})
        assert cross.status_code == 403, path
        unsigned = client.post(path, json=body, headers={"Origin": LOCAL, "X-XSRF-Token": "forged"})
        assert unsigned.status_code == 403 and "XSRF" in unsigned.json()["error"], path
        simple = client.post(path, content=json.dumps(body), headers={"Content-Type": "text/plain"})
        assert simple.status_code == 415, path
    assert client.get("/api/rig").json()["camera"]["exposure_us"] == before


def test_a_token_guards_the_console(console):
    with TestClient(create_console(*console, Access(token="s3cret-token-for-tests")), base_url=LOCAL) as c:
        for method, path in (("GET", "/api/rig"), ("GET", "/api/stream"), ("POST", "/api/camera")):
            answer = c.request(method, path, json={} if method == "POST" else None)
            assert answer.status_code == 403 and "token" in answer.json()["error"]
        assert c.get("/api/rig", headers={"Authorization": "token s3cret-token-for-tests"}).status_code == 200


def test_an_oversized_body_is_refused(client):
    answer = client.post(
        "/api/camera", content=b"{" + b" " * 2_000_000 + b"}", headers={"Content-Type": "application/json"}
    )
    assert answer.status_code == 413


def test_every_answer_carries_the_security_headers_and_no_cors(client):
    answers = [
        client.get("/"),
        client.get("/api/rig"),
        client.get("/api/camera/frame.png"),
        client.get("/api/stream", params={"limit": 1}),
        client.post("/api/camera", json={"exposure_us": -1}),
        client.get("/api/runs/none"),
        client.options(
            "/api/camera", headers={"Origin": "http://evil.example", "Access-Control-Request-Method": "POST"}
        ),
    ]
    for answer in answers:
        assert answer.headers["x-content-type-options"] == "nosniff", answer.request.url
        assert "frame-ancestors 'none'" in answer.headers["content-security-policy"]
        assert not any(h.startswith("access-control-") for h in answer.headers)
    assert answers[-1].status_code >= 400
