"""The EMVA 1288 datasheet (`datasheet.html`) in a real headless Chromium: every figure decodes, the summary table
holds the Table 2 quantities with values and units, the verdict is visible, nothing overflows the page, and on a
narrow screen the table moves below the figures."""

import numpy as np
import pytest
from selenium.webdriver.common.by import By

from tests.support.chromium import chromium
from uwlab.sim.devices.camera import SimTruth
from uwlab.experiments.emva.analysis import characterize
from uwlab.experiments.emva.datasheet import SheetInfo
from uwlab.experiments.emva.output import output_paths, write_characterization
from uwlab.experiments.emva.simulate import DirectBench
from uwlab.model.sensor import load_sensor_profile


@pytest.fixture(scope="module")
def datasheet(tmp_path_factory):
    truth = SimTruth.from_sensor_profile(
        load_sensor_profile("imx250m"), resolution_px=(64, 64), dark_current_e_per_s=200.0, dsnu_e=1.5, prnu_percent=1.0
    )
    bench = DirectBench(truth, 1.07e5, 0.6, seed=21)
    pt = bench.photon_transfer(
        np.linspace(2e3, 115e3, 40), dark_exposures_us=np.linspace(1e5, 6e5, 6), stack_exposure_us=50e3, stack_frames=16
    )
    result = characterize(pt)
    out = tmp_path_factory.mktemp("sheet")
    paths = output_paths(out, result, "cam", with_profile=True)
    write_characterization(
        result,
        pt,
        paths,
        name="cam",
        base=None,
        pixel_size_um=3.45,
        info=SheetInfo(vendor="uwlab", model="SimCam-IMX250M", serial="SIM0001"),
    )
    return paths.datasheet, result.values


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    driver = chromium(tmp_path_factory.mktemp("chromium-profile"))
    yield driver
    driver.quit()


def test_datasheet_in_chromium(datasheet, browser, tmp_path):
    path, values = datasheet
    browser.set_window_size(1280, 1000)
    browser.get(path.as_uri())
    assert "EMVA 1288 datasheet" in browser.title
    images = browser.find_elements(By.TAG_NAME, "img")
    assert len(images) == len(list(path.parent.glob("*.png"))) == 12  # every figure written, each inside the page
    assert all(
        browser.execute_script("return arguments[0].complete && arguments[0].naturalWidth > 300", img) for img in images
    )
    rows = browser.find_elements(By.CSS_SELECTOR, "#summary-table tr")
    text = {
        r.find_elements(By.TAG_NAME, "td")[0].text: r.find_elements(By.TAG_NAME, "td")[1].text
        for r in rows
        if r.find_elements(By.TAG_NAME, "td")
    }
    for symbol in (
        "η",
        "K",
        "1/K",
        "σ_d",
        "σ_y.dark",
        "SNR_max",
        "μ_e.min",
        "μ_e.sat",
        "DR",
        "DSNU1288",
        "PRNU1288.pix",
        "LE",
        "μ_I.mean",
        "μ_I.var",
    ):
        assert text.get(symbol) not in (None, "", "—"), symbol
    assert float(text["K"]) == pytest.approx(values["K_dn_per_e"], rel=1e-3)
    verdict = browser.find_element(By.CSS_SELECTOR, ".verdicts p.ok")
    assert verdict.is_displayed() and "Linear model holds" in verdict.text
    assert browser.execute_script("return document.documentElement.scrollWidth <= window.innerWidth")
    figure = browser.find_element(By.CSS_SELECTOR, ".summary figure")
    table = browser.find_element(By.ID, "summary-table")
    assert table.location["x"] > figure.location["x"] + figure.size["width"] - 1  # beside the figures
    browser.save_screenshot(str(tmp_path / "datasheet.png"))
    browser.set_window_size(600, 1000)
    table = browser.find_element(By.ID, "summary-table")
    figure = browser.find_element(By.CSS_SELECTOR, ".summary figure")
    assert table.location["y"] > figure.location["y"] + figure.size["height"]  # below them on a narrow screen
    assert browser.execute_script("return document.documentElement.scrollWidth <= window.innerWidth")
