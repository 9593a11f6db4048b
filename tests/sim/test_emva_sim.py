"""A characterisation of the simulated camera recovers its ground truth (accuracy stated in docs/emva.md)."""
import numpy as np
import pytest

from uwlab.drivers.sim.camera import SimTruth
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.emva.analysis import characterize
from uwlab.experiments.emva.from_dataset import IrradianceOverride, photon_transfer_from_points
from uwlab.experiments.emva.simulate import sim_truth_of, simulate_photon_transfer
from uwlab.model.sensor import load_sensor_profile

RATE_E_S = 1.07e5  # full well (10700 e-) at 100 ms


def sim_exposures_us():
    """Coarse below 90 % of the full well, 1 % steps around it (the EMVA saturation point is a sweep point)."""
    return np.r_[np.linspace(2e3, 88e3, 30), np.arange(89e3, 116e3, 1e3)]


@pytest.fixture(scope="module")
def sim_dataset(tmp_path_factory):
    truth = SimTruth.from_sensor_profile(load_sensor_profile("imx250m"), resolution_px=(128, 128),
                                         dark_current_e_per_s=200.0, dsnu_e=1.5, prnu_percent=1.0)
    root = tmp_path_factory.mktemp("emva") / "ds"
    simulate_photon_transfer(root, truth, rate_e_per_s=RATE_E_S, quantum_efficiency=0.6,
                             exposures_us=sim_exposures_us(), frames=4, seed=7)
    return root


@pytest.fixture(scope="module")
def result(sim_dataset):
    ds = Dataset.open(sim_dataset)
    return characterize(photon_transfer_from_points(ds.points(), ds.spectra())).values


def test_recovers_ground_truth(sim_dataset, result):
    truth = sim_truth_of(sim_dataset)
    assert result["K_dn_per_e"] == pytest.approx(truth["K_dn_per_e"], rel=0.02)
    assert result["quantum_efficiency"] == pytest.approx(truth["quantum_efficiency"], rel=0.03)
    assert result["dark_noise_e"] == pytest.approx(truth["dark_noise_e"], rel=0.10)
    assert result["saturation_e"] == pytest.approx(truth["saturation_e"], rel=0.05)
    assert result["saturation_e"] < truth["saturation_e"]  # the variance peaks before the full well
    assert result["dark_current_e_per_s"] == pytest.approx(truth["dark_current_e_per_s"], rel=0.05)
    assert result["dsnu_e"] == pytest.approx(truth["dsnu_e"], rel=0.10)
    assert result["prnu_percent"] == pytest.approx(truth["prnu_percent"], rel=0.10)
    assert result["linearity_error_percent"] < 0.5


def test_uncertainties_cover_the_truth(sim_dataset, result):
    truth = sim_truth_of(sim_dataset)
    for key in ("K_dn_per_e", "quantum_efficiency", "dark_noise_e"):
        assert result[f"{key}_std"] > 0
        # the posterior of the same straight lines (flat priors, unknown noise scale) has the least-squares width
        assert result[f"{key}_std_mcmc"] == pytest.approx(result[f"{key}_std"], rel=0.15)
        assert abs(result[key] - truth[key]) < 5 * result[f"{key}_std"] + 0.005 * truth[key]


def test_irradiance_override_matches_the_spectrometer(sim_dataset, result):
    ds = Dataset.open(sim_dataset)
    row = ds.points().iloc[0]
    spectrum = ds.spectra().query("point_index == 0")
    override = IrradianceOverride(spectrum_nm=spectrum["wavelength_nm"].to_numpy(),
                                  spectrum_w_m2_nm=spectrum["irradiance_w_m2_nm"].to_numpy())
    pt = photon_transfer_from_points(ds.points(), ds.spectra(), override=override)
    assert characterize(pt).values["quantum_efficiency"] == pytest.approx(result["quantum_efficiency"], rel=1e-9)
    mono = IrradianceOverride(irradiance_w_m2=float(row["irradiance_w_m2"]), wavelength_nm=525.0)
    pt = photon_transfer_from_points(ds.points(), ds.spectra(), override=mono)
    assert characterize(pt).values["quantum_efficiency"] == pytest.approx(result["quantum_efficiency"], rel=0.005)
