"""The tank rig with a USB spectrometer through python-seabreeze ([instruments.seabreeze_spectrometer])."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from tests.support.paths import DATA
from tests.support.plans import CAMPAIGN_DEFAULTS, CAMPAIGN_SWEEPS, write_plan
from tests.support.seabreeze_fake import SimulatedDevice, fake_seabreeze, lamp_counts_per_s, lamp_w_m2_nm, optical
from uwlab.drivers.ocean_insight import OceanInsightSpectrometer
from uwlab.drivers.ocean_insight import device as ocean_device
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.rigs import HardwareRig


def plan_with(tmp_path, **instruments):
    shutil.copy(DATA / "ocean_insight_calibration_3100k.csv", tmp_path / "lamp-cal.csv")
    path = write_plan(
        tmp_path / "plan.toml", "usb", CAMPAIGN_SWEEPS[:1], defaults=CAMPAIGN_DEFAULTS, instruments=instruments
    )
    return load_plan(path)


@pytest.fixture
def lamp(monkeypatch) -> SimulatedDevice:
    device = SimulatedDevice()
    device.signal_counts_per_s = lamp_counts_per_s(device)
    monkeypatch.setattr(ocean_device, "seabreeze_spectrometer_class", lambda backend: fake_seabreeze(device))
    return device


def test_rig_opens_the_usb_spectrometer_with_the_plans_calibration(tmp_path, lamp):
    plan = plan_with(tmp_path, seabreeze_spectrometer={"calibration": "lamp-cal.csv", "area_cm2": 0.1194591})
    with HardwareRig(plan) as rig:
        assert isinstance(rig.spectrometer, OceanInsightSpectrometer) and rig.spectrometer.dark_mode == "electric"
        rig.spectrometer.set_integration_ms(10.0)
        wavelength_nm, irradiance = rig.spectrometer.read_spectrum()
        assert lamp.is_open
    assert not lamp.is_open
    mask = optical(lamp)
    assert np.max(np.abs(irradiance[mask] / lamp_w_m2_nm(wavelength_nm)[mask] - 1)) < 2e-5  # area given to 7 digits


def test_rig_without_electric_dark_leaves_the_dark_to_the_sweep(tmp_path, lamp):
    lamp.dark_pixel_indices = []
    plan = plan_with(tmp_path, seabreeze_spectrometer={"calibration": "lamp-cal.csv"})
    with HardwareRig(plan) as rig:
        assert rig.spectrometer.dark_mode == "none"


def test_one_spectrometer_per_rig(tmp_path):
    with pytest.raises(ConfigError, match="give at most one of spectrometer_port and seabreeze_spectrometer"):
        plan_with(tmp_path, spectrometer_port="/dev/ttyUSB1", seabreeze_spectrometer={"calibration": "lamp-cal.csv"})


def test_identity_records_what_the_readings_use(tmp_path, lamp):
    plan = plan_with(tmp_path, seabreeze_spectrometer={"calibration": "lamp-cal.csv"})
    with HardwareRig(plan) as rig:
        assert rig.spectrometer.identity() == (
            "Ocean Insight FLAMES FLMS01234 (dark electric, nonlinearity corrected, A 0.1195 cm²)"
        )
