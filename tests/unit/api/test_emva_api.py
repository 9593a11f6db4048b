"""`uwlab.characterize` and `uwlab.Dataset` on a simulated photon transfer whose ground truth the code cannot see:
the figures recovered, the same numbers as the CLI, the XML, datasheet and sensor profile written and read back."""

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import uwlab
from uwlab.cli.main import main
from uwlab.experiments.emva.simulate import sim_truth_of, simulate_photon_transfer
from uwlab.model.sensor import load_sensor_profile
from uwlab.sim.devices.camera import SimTruth


@pytest.fixture(scope="module")
def photon_transfer(tmp_path_factory):
    root = tmp_path_factory.mktemp("emva") / "pt"
    truth = SimTruth.from_sensor_profile(
        load_sensor_profile("imx250m"), resolution_px=(48, 48), dark_current_e_per_s=150.0
    )
    simulate_photon_transfer(
        root,
        truth,
        rate_e_per_s=1.07e5,
        quantum_efficiency=0.6,
        exposures_us=np.linspace(2e3, 115e3, 40),
        seed=5,
        dark_exposures_us=np.linspace(0.2e6, 1.2e6, 4),
    )
    return root


def test_dataset_tables_are_the_recorded_points(photon_transfer):
    data = uwlab.Dataset.open(photon_transfer)
    assert len(data.points) == 44 and set(data.points["sweep_id"]) == {"sim-photon-transfer", "sim-dark-current"}
    assert set(data.spectra["position"]) == {"sensor"}
    assert data.summary["state"] == "complete" and data.summary["points_done"] == 44


def test_characterize_recovers_the_simulated_truth(photon_transfer):
    truth = sim_truth_of(photon_transfer)
    result = uwlab.characterize(uwlab.Dataset.open(photon_transfer), sweep="sim-photon-transfer")
    assert result.K_dn_per_e == pytest.approx(truth["K_dn_per_e"], rel=0.02)
    assert result.quantum_efficiency == pytest.approx(0.6, rel=0.03)
    assert result.to_pandas()["K_dn_per_e"] == result.K_dn_per_e
    with pytest.raises(AttributeError, match="no figure"):
        result.nonesuch  # noqa: B018


def test_characterize_equals_the_cli(photon_transfer, capsys):
    assert main(["emva", "characterize", str(photon_transfer), "--sweep", "sim-photon-transfer", "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    api = uwlab.characterize(photon_transfer, sweep="sim-photon-transfer").values
    assert api == cli


def test_xml_datasheet_and_profile(photon_transfer, tmp_path):
    result = uwlab.characterize(photon_transfer, sweep="sim-photon-transfer")
    root = ET.fromstring(result.to_xml())
    assert root.tag == "results"
    page = result.datasheet(tmp_path / "sheet.html").read_text()
    assert "data:image/png;base64" in page
    profile = result.sensor_profile(name="measured-cam", directory=tmp_path)
    assert profile.K_dn_per_e == pytest.approx(result.K_dn_per_e, rel=1e-4)
    # the measured profile drives a design: same sensor geometry, the measured gain
    design = uwlab.load_design(
        uwlab.config_path("design/example.toml"), sensor__profile=str(tmp_path / "measured-cam.toml")
    )
    assert design.sensor.K_dn_per_e == profile.K_dn_per_e
    assert uwlab.evaluate(design)["mean_dn"] > 0
