"""The explorer in a real browser: Debian's chromium and chromium-driver through selenium, against `uwlab explore`
running as a process on 127.0.0.1. Load the page, change a value and see the result change, see a warning beside
its number, save the design as TOML and load it back, open a shared URL, trigger a bad value and see the message,
run a sweep. A screenshot of the page is left in the test's folder for people to look at."""

import json
import time
from pathlib import Path
from urllib.parse import parse_qsl, urlsplit

import httpx2
import pytest
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support.ui import WebDriverWait

from uwlab.cli.main import main

from tests.support.chromium import chromium
from tests.support.paths import EXAMPLE
from tests.support.explorer_process import Explorer

WAIT_S = 60


@pytest.fixture(scope="module")
def explorer():
    server = Explorer(str(EXAMPLE))
    yield server
    code, err = server.stop()
    assert code == 130, err


@pytest.fixture(scope="module")
def downloads(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("downloads")


@pytest.fixture(scope="module")
def browser(downloads, tmp_path_factory):
    driver = chromium(tmp_path_factory.mktemp("chromium-profile"), (1600, 1000), downloads)
    driver.set_page_load_timeout(WAIT_S)
    yield driver
    driver.quit()


def wait(driver, condition, message: str):
    return WebDriverWait(driver, WAIT_S, poll_frequency=0.1).until(lambda d: condition(d), message)


def readout(driver) -> dict[str, str]:
    """{output key: value text} of the page's readout table."""
    return driver.execute_script(
        "return Object.fromEntries(Array.from(document.querySelectorAll('#readout tr'))"
        ".map((tr) => [tr.dataset.key, tr.querySelector('td.num').textContent]))"
    )


def open_page(driver, url: str) -> dict[str, str]:
    driver.get(url)
    wait(
        driver,
        lambda d: readout(d).get("snr_db") and d.find_element(By.ID, "error").get_attribute("hidden"),
        "the readout never appeared",
    )
    return readout(driver)


def set_field(driver, key: str, text: str) -> None:
    field = driver.find_element(By.ID, f"f-{key}")
    field.send_keys(Keys.CONTROL, "a")
    field.send_keys(text, Keys.ENTER)


def view(explorer, text: dict) -> dict:
    """The page's view of a design as the API gives it (rows by key)."""
    answer = httpx2.post(explorer.url + "api/view", json={"config": {}, "text": text}, timeout=30).json()
    return {row["key"]: row["text"] for row in answer["rows"]}


def page_texts(driver) -> dict[str, str]:
    return {key: value for key, value in parse_qsl(urlsplit(driver.current_url).query)}


def test_change_a_value_and_see_the_result_change(browser, explorer, tmp_path):
    before = open_page(browser, explorer.url)
    set_field(browser, "lens.f_number", "4")
    wait(browser, lambda d: readout(d)["snr_db"] != before["snr_db"], "SNR did not change")
    wait(browser, lambda d: page_texts(d).get("lens.f_number") == "4", "the URL does not hold the design")
    after = readout(browser)
    assert after == view(explorer, page_texts(browser))  # the page shows the server's numbers, as the CLI words them
    assert float(after["snr_db"]) < float(before["snr_db"])  # two stops less light
    browser.save_screenshot(str(tmp_path / "explorer.png"))


def test_warning_beside_its_number(browser, explorer):
    open_page(browser, explorer.url)
    row = browser.find_element(By.CSS_SELECTOR, '#readout tr[data-key="exposure_s"]')
    assert "warn" in row.get_attribute("class")
    assert "motion blur" in row.find_element(By.CSS_SELECTOR, ".badge").text
    set_field(browser, "operation.exposure_s", "max-blur")
    wait(
        browser,
        lambda d: not d.find_elements(By.CSS_SELECTOR, '#readout tr[data-key="exposure_s"] .badge'),
        "the blur warning stayed after the exposure was set to the blur limit",
    )


def test_bad_value_shows_the_message(browser, explorer):
    open_page(browser, explorer.url)
    set_field(browser, "lens.f_number", "0")
    banner = browser.find_element(By.ID, "error")
    wait(browser, lambda d: banner.get_attribute("hidden") is None, "no error shown")
    expected = httpx2.post(explorer.url + "api/design", json={"set": {"lens.f_number": 0}}, timeout=30).json()["error"]
    assert banner.text == "⚠ " + expected
    field = browser.find_element(By.CSS_SELECTOR, '.field[data-key="lens.f_number"]')
    assert "error" in field.get_attribute("class") and expected in field.text
    set_field(browser, "lens.f_number", "2.8")
    wait(browser, lambda d: banner.get_attribute("hidden") is not None, "the error stayed after a good value")


def test_save_and_load_a_toml(browser, explorer, downloads, capsys):
    open_page(browser, explorer.url)
    set_field(browser, "light.luminous_flux_lm", "12345.6")
    wait(browser, lambda d: page_texts(d).get("light.luminous_flux_lm") == "12345.6", "value not taken")
    wait(browser, lambda d: d.find_element(By.ID, "status").text.startswith("evaluated"), "not evaluated")
    shown = readout(browser)
    browser.find_element(By.ID, "save").click()
    saved = downloads / "design.toml"
    wait(browser, lambda d: saved.exists() and saved.stat().st_size > 0, "no design.toml downloaded")
    time.sleep(0.5)  # the download is renamed into place when complete
    assert main(["design", str(saved), "--json"]) == 0
    from_cli = json.loads(capsys.readouterr().out)
    assert (
        from_cli
        == httpx2.post(explorer.url + "api/design", json={"config": {}, "text": page_texts(browser)}, timeout=30).json()
    )
    set_field(browser, "light.luminous_flux_lm", "999")
    wait(browser, lambda d: readout(d)["mean_dn"] != shown["mean_dn"], "value not changed")
    browser.find_element(By.ID, "load-file").send_keys(str(saved))
    wait(
        browser,
        lambda d: d.find_element(By.ID, "f-light.luminous_flux_lm").get_attribute("value") == "12345.6",
        "the loaded TOML did not fill the form",
    )
    wait(browser, lambda d: readout(d) == shown, "the loaded design does not show the saved numbers")


def test_shared_url_opens_the_design(browser, explorer):
    open_page(browser, explorer.url)
    set_field(browser, "operation.altitude_m", "3.5")
    wait(browser, lambda d: page_texts(d).get("operation.altitude_m") == "3.5", "URL not updated")
    wait(browser, lambda d: d.find_element(By.ID, "status").text.startswith("evaluated"), "not evaluated")
    shared, shown = browser.current_url, readout(browser)
    browser.get("about:blank")
    assert open_page(browser, shared) == shown
    assert browser.find_element(By.ID, "f-operation.altitude_m").get_attribute("value") == "3.5"


def test_sweep_panel_draws_the_sweep(browser, explorer):
    open_page(browser, explorer.url)
    browser.find_element(By.ID, "sweep-run").click()
    wait(
        browser,
        lambda d: d.execute_script(
            "const p = document.getElementById('fig-sweep');return p.data && p.data.length && p.data[0].y.length"
        ),
        "no sweep drawn",
    )
    status = browser.find_element(By.ID, "sweep-status").text
    assert status.split()[0].isdigit() and "points" in status


def test_beyond_the_loopback_the_page_needs_the_printed_token(browser, tmp_path):
    """`--host 0.0.0.0`: a warning, a token in the printed URL; the page works with it and not without it."""
    server = Explorer(str(EXAMPLE), "--host", "0.0.0.0")
    try:
        parts = urlsplit(server.url)
        token = dict(parse_qsl(parts.query))["token"]
        assert len(token) >= 24
        local = f"http://127.0.0.1:{parts.port}/"
        assert httpx2.get(local + "api/config", timeout=30).status_code == 403
        browser.delete_all_cookies()
        browser.get(local)
        assert "token is required" in browser.page_source
        before = open_page(browser, f"{local}?token={token}")
        assert "token=" not in browser.current_url  # the token went to a cookie
        set_field(browser, "lens.f_number", "4")
        wait(browser, lambda d: readout(d)["snr_db"] != before["snr_db"], "SNR did not change with the token")
        browser.save_screenshot(str(tmp_path / "explorer-token.png"))
    finally:
        code, err = server.stop()
    assert code == 130
    assert err.count("warning: listening on 0.0.0.0") == 1
