"""`uwlab light calibrate` with a lab's own gear, in-process: a Thorlabs DC2200 LED driver on pyvisa-sim (by its
instrument definition; a CV/CC supply's constant-current check needs a twin whose current follows the set one,
which pyvisa-sim's constants are not) lighting an Ocean Insight Flame behind seabreeze's own API
(`tests.support.seabreeze_fake`).

The truth the code under test cannot see: the Flame's light is the 3100 K lamp scaled by the supply's drive current
as the supply itself reads it back (an LED's flux is proportional to its current), so the calibration curve must
be the level, the spectra the lamp, and the light off at the end."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import pytest
import yaml

from tests.support.cli import one_line_error
from tests.support.paths import CONFIGS, DATA
from tests.support.seabreeze_fake import CC3_AREA_CM2, SimulatedDevice, fake_seabreeze, lamp_counts_per_s, lamp_w_m2_nm
from tests.support.seabreeze_fake import optical
from uwlab.cli.main import main
from uwlab.drivers import instruments
from uwlab.drivers.ocean_insight import device as ocean_device
from uwlab.experiments.acquisition.light_calibration import load_light_calibration

SIM = CONFIGS / "instruments" / "sim" / "thorlabs-dc2200.yaml"
RESOURCE = next(iter(yaml.safe_load(SIM.read_text())["resources"]))
CALIBRATION = str(DATA / "ocean_insight_calibration_3100k.csv")
LIGHT = ["--instrument", "thorlabs-dc2200", "--resource", RESOURCE, "--visa-library", f"{SIM}@sim"]
SPECTROMETER = ["--spectrometer-instrument", "ocean-insight", "--calibration", CALIBRATION]
SPECTROMETER += ["--area-cm2", repr(CC3_AREA_CM2), "--integration-ms", "10"]


@dataclass
class LitFlame(SimulatedDevice):
    """The Flame under the LED: the lamp's counts times the supply's read-back current over its full scale."""

    full_counts_per_s: np.ndarray | None = None
    supply: object = None
    full_scale_a: float = 1.0

    def raw(self) -> np.ndarray:
        on = self.supply is not None and self.supply.output()
        self.signal_counts_per_s = self.full_counts_per_s * (self.supply.drive() / self.full_scale_a if on else 0.0)
        return super().raw()


@pytest.fixture
def rig(monkeypatch):
    flame = LitFlame()
    flame.full_counts_per_s = lamp_counts_per_s(flame)
    opened = []
    real_open = instruments.open_light_instrument

    def open_and_watch(*args, **kwargs):
        light = real_open(*args, **kwargs)
        opened.append(light)
        flame.supply = light
        return light

    monkeypatch.setattr(instruments, "open_light_instrument", open_and_watch)
    monkeypatch.setattr(ocean_device, "seabreeze_spectrometer_class", lambda backend: fake_seabreeze(flame))
    return flame, opened


def test_calibration_curve_is_the_drive_and_the_spectra_the_lamp(rig, tmp_path, capsys):
    flame, opened = rig
    out = tmp_path / "led.csv"
    argv = ["light", "calibrate", *LIGHT, *SPECTROMETER, "--levels", "5", "--out", str(out), "--json"]
    assert main(argv) == 0
    printed = json.loads(capsys.readouterr().out)
    curve = load_light_calibration(out)
    assert printed["level"] == curve.level.tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]
    full = curve.irradiance_w_m2[-1]
    assert curve.irradiance_w_m2 / full == pytest.approx(curve.level, abs=1e-3)
    mask = optical(flame)
    assert np.max(np.abs(curve.irradiance_w_m2_nm[-1][mask] / lamp_w_m2_nm(curve.wavelength_nm)[mask] - 1)) < 1e-3
    header = out.read_text().splitlines()[:3]
    assert "thorlabs-dc2200 on" in header[1] and "Thorlabs" in header[1] and "ocean-insight" in header[2]
    (light,) = opened
    assert light.safe_state_reached is True  # output off on exit
    assert not flame.is_open


def test_rig_maximum_current_is_full_level(rig, tmp_path, capsys):
    """With --max-current-a 0.25 the driver never exceeds 0.25 A: level 1 gives a quarter of the full-scale light."""
    flame, _ = rig
    out = tmp_path / "led.csv"
    argv = ["light", "calibrate", *LIGHT, "--max-current-a", "0.25", *SPECTROMETER, "--levels", "2", "--out", str(out)]
    assert main(argv) == 0
    curve = load_light_calibration(out)
    mask = optical(flame)
    assert np.median(curve.irradiance_w_m2_nm[-1][mask] / lamp_w_m2_nm(curve.wavelength_nm)[mask]) == pytest.approx(
        0.25, rel=1e-3
    )


@pytest.mark.parametrize(
    ("argv", "names"),
    [
        (["--light", "/dev/null", *LIGHT, *SPECTROMETER], "light"),
        ([*LIGHT[:2], *SPECTROMETER], "resource"),
        ([*LIGHT, "--spectrometer-instrument", "ocean-insight"], "calibration"),
        ([*LIGHT, "--spectrometer", "/dev/null", "--calibration", CALIBRATION], "calibration"),
        ([*LIGHT], "spectrometer"),
        ([*LIGHT, *SPECTROMETER, "--dark", "/no/such/dark.csv"], "dark"),
        ([*LIGHT[:4], "--visa-library", "/no/such.yaml@sim", *SPECTROMETER], "no/such.yaml"),
    ],
)
def test_bad_input_is_one_line_nothing_opened_nothing_written(rig, tmp_path, capsys, argv, names):
    _, opened = rig
    out = tmp_path / "led.csv"
    assert names in one_line_error(capsys, ["light", "calibrate", *argv, "--out", str(out)])
    assert not out.exists() and not opened


@dataclass
class TwinLitFlame(SimulatedDevice):
    """The Flame under the LED on the CV/CC supply twin: the lamp's counts times the current the twin's load truly
    draws over its full scale (what the driver reads back plays no part)."""

    full_counts_per_s: np.ndarray | None = None
    twin: object = None
    full_scale_a: float = 0.5

    def raw(self) -> np.ndarray:
        self.signal_counts_per_s = self.full_counts_per_s * (self.twin.point().current_a / self.full_scale_a)
        return super().raw()


def test_calibrating_an_led_on_a_cv_cc_supply_twin(monkeypatch, tmp_path, capsys):
    from uwlab.sim.devices.supply import SupplyTwin, serve

    twin = SupplyTwin("keysight-e36100", seed=6)
    flame = TwinLitFlame(twin=twin)
    flame.full_counts_per_s = lamp_counts_per_s(flame)
    monkeypatch.setattr(ocean_device, "seabreeze_spectrometer_class", lambda backend: fake_seabreeze(flame))
    out = tmp_path / "led.csv"
    with serve(twin, transport="tcp") as resource:
        light = ["--instrument", "keysight-e36100", "--resource", resource, "--visa-library", "@py"]
        light += ["--max-current-a", "0.5", "--forward-voltage-v", "3.4"]
        assert main(["light", "calibrate", *light, *SPECTROMETER, "--levels", "3", "--out", str(out)]) == 0
        assert twin.voltage_set_v == pytest.approx(4.4) and not twin.output_on  # compliance set; dark at the end
    curve = load_light_calibration(out)
    assert curve.irradiance_w_m2 / curve.irradiance_w_m2[-1] == pytest.approx([0.0, 0.5, 1.0], abs=2e-3)
