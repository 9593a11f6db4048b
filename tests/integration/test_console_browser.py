"""The rig console in a real browser: Debian's chromium and chromium-driver through selenium, against
`uwlab console --sim` running as a process on 127.0.0.1. The page shows the live image, its histogram, the clipped
pixels painted over it and the sharpness; changing the exposure changes the image and the read-back; a run started,
paused, resumed and finished from the page gives the dataset `uwlab sweep --sim` gives (point by point), the model's
predicted band drawn under its points; a second
browser session watches read-only. Screenshots are left in the test's folder for people to look at."""

from __future__ import annotations

import time

import httpx2
import numpy as np
import pytest
from selenium.common.exceptions import StaleElementReferenceException
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support.ui import WebDriverWait

from tests.support.chromium import chromium
from tests.support.console_process import Console
from tests.support.plans import write_plan
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.session import run_session
from uwlab.experiments.dataset import Dataset

WAIT_S = 90
TIMING = ("t_start_ns", "t_end_ns", "readback_t_start_ns", "readback_t_end_ns")
# The fraction of the shown image's pixels painted red (the clipping overlay), from the page's own canvas.
RED_FRACTION_JS = """
const canvas = document.getElementById('live');
const d = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height).data;
let red = 0; for (let i = 0; i < d.length; i += 4) if (d[i] === 255 && d[i + 1] === 0 && d[i + 2] === 40) red++;
return [red / (d.length / 4), Number(canvas.dataset.frameId || -1)];
"""

# The run plot's traces of one kind (the page's `meta`: points, band, median), and the band fills Plotly drew (SVG
# paths of a filled trace with an outline).
TRACES_JS = "return document.getElementById('run-points').data.filter((t) => t.meta === arguments[0]).length;"
FILLS_JS = """
return [...document.querySelectorAll('#run-points .scatterlayer .trace path.js-fill')]
  .filter((p) => (p.getAttribute('d') || '').length > 20).length;
"""


@pytest.fixture(scope="module")
def console():
    server = Console("--sim", "--max-fps", "8")
    yield server
    code, err = server.stop()
    assert code == 130, err


def chrome(profile):
    driver = chromium(profile, (1400, 1500))
    driver.set_page_load_timeout(WAIT_S)
    return driver


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    driver = chrome(tmp_path_factory.mktemp("chromium-profile"))
    yield driver
    driver.quit()


def wait(driver, condition, message: str):
    """Wait for ``condition``; an element the page replaced between finding and reading it is read again."""
    waiter = WebDriverWait(driver, WAIT_S, poll_frequency=0.1, ignored_exceptions=(StaleElementReferenceException,))
    return waiter.until(lambda d: condition(d), message)


def text(driver, element_id: str) -> str:
    """An element's text, read in one step (the page rewrites its readouts many times a second)."""
    return driver.execute_script("return document.getElementById(arguments[0]).innerText.trim()", element_id)


def set_input(driver, element_id: str, value: str) -> None:
    field = driver.find_element(By.ID, element_id)
    field.send_keys(Keys.CONTROL, "a")
    field.send_keys(value)


def apply_exposure(driver, exposure_us: float) -> None:
    set_input(driver, "exposure_us", f"{exposure_us:g}")
    driver.find_element(By.ID, "apply-camera").click()
    wait(driver, lambda d: text(d, "readback").startswith(f"{exposure_us:g} µs"), "no read-back of the exposure")
    wait(driver, lambda d: f", {exposure_us:g} µs" in text(d, "s-frame"), "no frame at the new exposure")


def light(driver, on: bool, level: float) -> None:
    row = driver.find_element(By.CSS_SELECTOR, '#lights .light[data-name="light"]')
    box = row.find_element(By.CSS_SELECTOR, ".light-on")
    if box.is_selected() != on:
        box.click()
    level_field = row.find_element(By.CSS_SELECTOR, ".light-level")
    level_field.send_keys(Keys.CONTROL, "a")
    level_field.send_keys(f"{level:g}")
    row.find_element(By.CSS_SELECTOR, ".light-apply").click()
    wait(
        driver,
        lambda d: (
            ("read back: on" if on else "read back: off")
            in d.find_element(By.CSS_SELECTOR, '#lights .light[data-name="light"] .readback').text
        ),
        "no read-back of the light",
    )


def mean_dn(driver) -> float:
    return float(text(driver, "s-mean").split()[0])


def test_the_live_page(browser, console, tmp_path):
    browser.get(console.url)
    wait(browser, lambda d: d.execute_script("return document.getElementById('live').dataset.frameId"), "no image")
    assert text(browser, "control") == "controlling the rig"
    wait(browser, lambda d: d.find_elements(By.CSS_SELECTOR, "#histogram .barlayer .trace"), "no histogram")
    wait(browser, lambda d: float(text(d, "f-now")) > 0, "no sharpness")
    wait(browser, lambda d: d.find_elements(By.CSS_SELECTOR, "#focus-trace .scatterlayer .trace"), "no trace")
    assert "set the lens to" in text(browser, "focus-model")

    # The light on and a long exposure: pixels clip, and the page paints them red.
    light(browser, True, 1.0)
    apply_exposure(browser, 3000)
    wait(browser, lambda d: float(text(d, "s-sat").split()[0]) > 1.0, "nothing clipped")
    red, _ = wait(browser, lambda d: (r := d.execute_script(RED_FRACTION_JS))[0] > 0.01 and r, "no clipping overlay")
    stats = httpx2.get(console.url + "api/camera/stats", timeout=30).json()
    assert red == pytest.approx(stats["saturated_fraction"], rel=0.1)
    browser.save_screenshot(str(tmp_path / "console-clipping.png"))

    # A shorter exposure: the read-back follows, the image darkens (a linear sensor: about 1/6 of the signal above
    # the dark level), and nothing clips.
    apply_exposure(browser, 500)
    wait(browser, lambda d: float(text(d, "s-sat").split()[0]) == 0.0, "still clipping at 500 µs")
    assert httpx2.get(console.url + "api/rig", timeout=30).json()["camera"]["exposure_us"] == 500.0
    bright = mean_dn(browser)
    red, _ = browser.execute_script(RED_FRACTION_JS)
    assert red < 1e-4  # at most a hot pixel or two of the sim's sensor
    apply_exposure(browser, 250)
    assert mean_dn(browser) < 0.6 * bright
    browser.find_element(By.ID, "show-peaking").click()
    time.sleep(1.0)
    browser.save_screenshot(str(tmp_path / "console-live.png"))


def test_a_second_session_watches(console, tmp_path):
    watcher = chrome(tmp_path / "profile")
    try:
        watcher.get(console.url)
        wait(watcher, lambda d: text(d, "control") == "watching (read-only)", "the second session is not a watcher")
        wait(watcher, lambda d: d.execute_script("return document.getElementById('live').dataset.frameId"), "no image")
        answer = watcher.execute_script(
            "const r = await fetch('/api/camera', {method: 'POST', headers: {'Content-Type': 'application/json', "
            "'X-XSRF-Token': (document.cookie.match(/_xsrf=([^;]*)/) || [])[1]}, "
            "body: JSON.stringify({exposure_us: 99})});"
            "return [r.status, (await r.json()).error];"
        )
        assert answer[0] == 403 and "watches" in answer[1]
    finally:
        watcher.quit()


def small_plan(path):
    return write_plan(
        path,
        "console-browser-run",
        [
            {"id": "f2", "sensor": "imx250m", "lens": {"focal_length_mm": 30, "f_number": 2.0}, "light_level": 0.35},
            {"id": "f4", "sensor": "imx250m", "lens": {"focal_length_mm": 12, "f_number": 4.0}},
        ],
        camera={"pixel_format": "Mono12", "window": [1192, 1000, 16, 12]},
        defaults={
            "kind": "exposure",
            "values": {"start": 50, "stop": 1500, "num": 4, "spacing": "log"},
            "frames_per_point": 2,
            "dark": "point",
            "dark_frames": 2,
            "spectrometer": ["target"],
            "spectrometer_integration_ms": 10,
        },
    )


def run_state(driver) -> str:
    return driver.find_element(By.ID, "run-status").get_attribute("data-state") or ""


def test_a_run_from_the_page_is_the_dataset_of_uwlab_sweep(browser, console, tmp_path):
    plan = small_plan(tmp_path / "plan.toml")
    browser.get(console.url)
    wait(browser, lambda d: text(d, "control") == "controlling the rig", "not in control")
    set_input(browser, "run-plan", str(plan))
    set_input(browser, "run-out", str(tmp_path / "console-run"))
    browser.find_element(By.ID, "run-start").click()
    wait(browser, lambda d: run_state(d) == "running", "the run did not start")
    wait(browser, lambda d: d.find_element(By.ID, "run-pause").is_enabled(), "no pause button")
    browser.find_element(By.ID, "run-pause").click()
    wait(browser, lambda d: run_state(d) == "paused", "the run did not pause")
    assert "safe state" in text(browser, "run-status")
    done_at_pause = text(browser, "run-status")
    time.sleep(1.0)
    assert text(browser, "run-status") == done_at_pause  # nothing measured while paused
    browser.find_element(By.ID, "run-resume").click()
    wait(browser, lambda d: run_state(d) == "done", "the run did not finish")
    assert "8/8 points" in text(browser, "run-status")
    # The points of both sweeps, and under them the model's band (shaded) and median for the sweep at full light
    # (the dimmed one is not predicted: GET /api/runs/ID/prediction says why, and so does the page).
    run_id = httpx2.get(console.url + "api/runs", timeout=30).json()["runs"][-1]["id"]
    prediction = httpx2.get(console.url + f"api/runs/{run_id}/prediction", timeout=30).json()
    assert [c["sweep_id"] for c in prediction["configurations"]] == ["f4"] and set(prediction["skipped"]) == {"f2"}
    wait(browser, lambda d: d.execute_script(TRACES_JS, "points") == 2, "no points plotted")
    wait(browser, lambda d: d.execute_script(FILLS_JS) == 1, "no band drawn")
    assert browser.execute_script(TRACES_JS, "median") == browser.execute_script(TRACES_JS, "band") == 1
    assert "predicted from design" in text(browser, "run-prediction") and "f2: light level 0.35" in text(
        browser, "run-prediction"
    )
    browser.save_screenshot(str(tmp_path / "console-run.png"))

    reference = run_session(load_plan(plan), tmp_path / "sweep-run", sim=True)  # `uwlab sweep PLAN --sim`
    ours, theirs = Dataset.open(tmp_path / "console-run"), Dataset.open(reference)
    a, b = ours.points(), theirs.points()
    assert len(a) == len(b) == 8
    for column in (c for c in b.columns if c not in TIMING):
        for x, y in zip(a[column], b[column], strict=True):
            assert np.array_equal(np.asarray(x), np.asarray(y), equal_nan=np.asarray(x).dtype.kind == "f"), column
    sa, sb = ours.spectra(), theirs.spectra()
    assert np.array_equal(sa.to_numpy(), sb.to_numpy())
