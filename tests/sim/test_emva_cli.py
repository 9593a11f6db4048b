"""`uwlab emva`: characterize a dataset or a descriptor, outputs, no overwriting, the profile in `uwlab design`,
one-line errors."""
import json

import numpy as np
import pytest

from uwlab.cli.main import main
from uwlab.drivers.sim.camera import SimTruth
from uwlab.experiments.emva.simulate import simulate_photon_transfer
from uwlab.model.sensor import load_sensor_profile

from tests.sim.conftest import EXAMPLE


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    truth = SimTruth.from_sensor_profile(load_sensor_profile("imx250m"), resolution_px=(64, 64),
                                         dark_current_e_per_s=200.0, dsnu_e=1.5, prnu_percent=1.0)
    root = tmp_path_factory.mktemp("emva_cli") / "ds"
    simulate_photon_transfer(root, truth, rate_e_per_s=1.07e5, quantum_efficiency=0.6,
                             exposures_us=np.linspace(3e3, 120e3, 40), frames=2, seed=3)
    return root


def run_json(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr().out
    assert code == 0
    return json.loads(out)


def test_characterize_json_and_outputs(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    doc = run_json(capsys, "emva", "characterize", str(dataset), "--out", str(out), "--json", "--name", "cam")
    for key in ("K_dn_per_e", "quantum_efficiency", "dark_noise_e", "saturation_e", "snr_max_db", "dynamic_range_db",
                "linearity_error_percent", "dark_current_e_per_s", "dsnu_e", "prnu_percent",
                "K_dn_per_e_std", "quantum_efficiency_std", "dark_noise_e_std"):
        assert isinstance(doc[key], float), key
    assert doc["K_dn_per_e"] == pytest.approx(0.3473, rel=0.03)
    names = {p.name for p in out.iterdir()}
    assert names == {"emva.json", "photon_transfer.png", "snr.png", "linearity.png", "dark_current.png",
                     "cam.toml", "cam_qe.csv"}
    assert json.loads((out / "emva.json").read_text())["K_dn_per_e"] == doc["K_dn_per_e"]
    assert (out / "snr.png").read_bytes()[:4] == b"\x89PNG"
    profile = load_sensor_profile(str(out / "cam.toml"))
    assert profile.K_dn_per_e == pytest.approx(doc["K_dn_per_e"], rel=1e-4)
    assert profile.qe["combined"] == pytest.approx([doc["quantum_efficiency"]] * 2, rel=1e-5)
    # never overwrite
    before = (out / "emva.json").read_bytes()
    assert main(["emva", "characterize", str(dataset), "--out", str(out), "--name", "cam"]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert (out / "emva.json").read_bytes() == before
    # the profile drives `uwlab design` directly
    design = tmp_path / "design.toml"
    design.write_text(EXAMPLE.read_text().replace('profile = "imx250m"', f'profile = "{out / "cam.toml"}"'))
    measured = run_json(capsys, "design", str(design), "--json")
    expected_dn = profile.K_dn_per_e * measured["mean_electrons"] + profile.dark_offset_dn
    assert measured["mean_dn"] == pytest.approx(expected_dn, rel=1e-6)
    assert measured["mean_electrons"] > 0


def test_summary_is_readable(dataset, capsys):
    assert main(["emva", "characterize", str(dataset)]) == 0
    out = capsys.readouterr().out
    assert "system gain K" in out and "DN/e-" in out and "±" in out


def test_export_then_characterize_descriptor(dataset, tmp_path, capsys):
    desc_dir = tmp_path / "desc"
    doc = run_json(capsys, "emva", "export", str(dataset), "--out", str(desc_dir), "--image-size", "64x48", "--json")
    assert doc["synthetic_images"] is True
    a = run_json(capsys, "emva", "characterize", str(dataset), "--json")
    b = run_json(capsys, "emva", "characterize", "--descriptor", doc["descriptor"], "--json")
    assert b["K_dn_per_e"] == pytest.approx(a["K_dn_per_e"], rel=0.03)
    assert b["quantum_efficiency"] == pytest.approx(a["quantum_efficiency"], rel=0.03)


@pytest.mark.parametrize("argv, words", [
    (["emva", "characterize"], "exactly one"),
    (["emva", "characterize", "/nonexistent/ds"], "not a dataset"),
    (["emva", "characterize", "--descriptor", "/nonexistent/d.txt"], "/nonexistent/d.txt"),
    (["emva", "characterize", "DS", "--irradiance", "0.5"], "--wavelength-nm"),
    (["emva", "characterize", "DS", "--irradiance", "-1"], "--irradiance"),
    (["emva", "characterize", "DS", "--sweep", "nope"], "--sweep"),
])
def test_bad_input_is_one_line(dataset, capsys, argv, words):
    argv = [str(dataset) if a == "DS" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1
