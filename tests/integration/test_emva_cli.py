"""`uwlab emva`: characterize a dataset or a descriptor (linear and general model), its outputs (JSON, datasheet,
XML with the reference implementation's names, figures, profile), no overwriting, a fleet of cameras, one-line errors,
and the shipped EMVA plan on the simulated bench."""

import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import scipy

import uwlab
from uwlab.cli.main import main
from uwlab.sim.devices.camera import SimTruth
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.emva.simulate import simulate_photon_transfer
from uwlab.model.sensor import load_sensor_profile

from tests.support.paths import EXAMPLE, ROOT
from tests.support.plans import write_plan

# The result names of the EMVA 1288 reference implementation (github.com/EMVA1288/emva1288,
# doc/datasets/datasets_results.rst and the emva1288 tags of process/results.py), by section.
REFERENCE_NAMES = {
    "info": {"index_start"},
    "sensitivity": {
        "u_p_sat",
        "u_p_sat_area",
        "u_e_sat",
        "u_e_sat_area",
        "SNR_max",
        "SNR_max_dB",
        "SNR_max_bit",
        "inverse_SNR_max",
        "sigma_y_dark",
        "sigma_d",
        "K",
        "inverse_K",
        "R",
        "QE",
        "u_p_min",
        "u_p_min_area",
        "u_e_min",
        "u_e_min_area",
        "DR",
        "DR_dB",
        "index_u_ysat",
        "index_sensitivity_min",
        "index_sensitivity_max",
    },
    "linearity": {"LE_min", "LE_max", "index_linearity_min", "index_linearity_max"},
    "dark_current": {"u_I_mean", "u_I_mean_DN", "u_I_var", "u_I_var_DN"},
    "spatial": {
        "s_2_y",
        "s_2_y_dark",
        "s_2_y_measured",
        "s_2_y_measured_dark",
        "sigma_2_y_stack",
        "sigma_2_y_stack_dark",
        "s_2_y_cav",
        "s_2_y_cav_dark",
        "s_2_y_rav",
        "s_2_y_rav_dark",
        "s_2_y_col",
        "s_2_y_col_dark",
        "s_2_y_row",
        "s_2_y_row_dark",
        "s_2_y_pixel",
        "s_2_y_pixel_dark",
        "DSNU1288",
        "DSNU1288_DN",
        "DSNU1288_row",
        "DSNU1288_col",
        "DSNU1288_pixel",
        "PRNU1288",
        "PRNU1288_row",
        "PRNU1288_col",
        "PRNU1288_pixel",
    },
    "defect_pixel": {"histogram_DSNU", "histogram_DSNU_accumulated", "histogram_PRNU", "histogram_PRNU_accumulated"},
}


def make_dataset(root, seed=3, prnu=1.0):
    truth = SimTruth.from_sensor_profile(
        load_sensor_profile("imx250m"),
        resolution_px=(64, 64),
        dark_current_e_per_s=200.0,
        dsnu_e=1.5,
        prnu_percent=prnu,
    )
    simulate_photon_transfer(
        root,
        truth,
        rate_e_per_s=1.07e5,
        quantum_efficiency=0.6,
        exposures_us=np.linspace(3e3, 120e3, 40),
        frames=2,
        seed=seed,
        dark_exposures_us=np.linspace(1e5, 6e5, 6),
    )
    return root


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("emva_cli") / "ds")


def run_json(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr().out
    assert code == 0
    return json.loads(out)


def test_characterize_json_and_outputs(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    doc = run_json(capsys, "emva", "characterize", str(dataset), "--out", str(out), "--json", "--name", "cam")
    for key in (
        "K_dn_per_e",
        "quantum_efficiency",
        "dark_noise_e",
        "saturation_e",
        "snr_max_db",
        "dynamic_range_db",
        "linearity_error_percent",
        "dark_current_e_per_s",
        "dsnu_e",
        "prnu_percent",
        "K_dn_per_e_std",
        "quantum_efficiency_std",
        "sensitivity_threshold_photons",
    ):
        assert isinstance(doc[key], float), key
    assert doc["K_dn_per_e"] == pytest.approx(0.3473, rel=0.03)
    names = {p.name for p in out.iterdir()}
    assert {
        "emva.json",
        "datasheet.html",
        "emva1288.xml",
        "photon_transfer.png",
        "snr.png",
        "linearity.png",
        "stability.png",
        "dark_current.png",
        "spatial_variances.png",
        "cam.toml",
        "cam_qe.csv",
    } == names
    assert json.loads((out / "emva.json").read_text())["K_dn_per_e"] == doc["K_dn_per_e"]
    assert (out / "snr.png").read_bytes()[:4] == b"\x89PNG"
    html = (out / "datasheet.html").read_text()
    assert html.count("data:image/png;base64,") == 6 and "Quantum efficiency" in html and "<script" not in html
    profile = load_sensor_profile(str(out / "cam.toml"))
    assert profile.K_dn_per_e == pytest.approx(doc["K_dn_per_e"], rel=1e-4)
    # never overwrite
    before = (out / "emva.json").read_bytes()
    assert main(["emva", "characterize", str(dataset), "--out", str(out), "--name", "cam"]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert (out / "emva.json").read_bytes() == before
    # the profile drives `uwlab design` directly
    design = tmp_path / "design.toml"
    design.write_text(EXAMPLE.read_text().replace('profile = "imx250m"', f'profile = "{out / "cam.toml"}"'))
    measured = run_json(capsys, "design", str(design), "--json")
    assert measured["mean_dn"] == pytest.approx(
        profile.K_dn_per_e * measured["mean_electrons"] + profile.dark_offset_dn, rel=1e-6
    )


def test_xml_has_the_reference_names_and_our_values(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    doc = run_json(capsys, "emva", "characterize", str(dataset), "--out", str(out), "--json")
    root = ET.parse(out / "emva1288.xml").getroot()
    assert root.tag == "results"
    found = {section.tag: {e.tag for e in section} for section in root}
    for section, names in REFERENCE_NAMES.items():
        assert names <= found[section], (section, names - found[section])
    value = lambda section, name: root.find(f"{section}/{name}/Value").text  # noqa: E731
    assert float(value("sensitivity", "K")) == doc["K_dn_per_e"]
    assert float(value("sensitivity", "QE")) == pytest.approx(100 * doc["quantum_efficiency"])
    assert float(value("sensitivity", "u_p_min")) == doc["sensitivity_threshold_photons"]
    assert float(value("dark_current", "u_I_mean")) == doc["dark_current_e_per_s"]
    assert float(value("spatial", "PRNU1288")) == doc["prnu_percent"]
    assert value("spatial", "sigma_2_y_stack") == "nan"  # no stacks in a sweep dataset
    assert root.find("sensitivity/K/Unit").text == "$DN/e^-$"


def test_every_output_names_the_versions_and_the_cpu(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    doc = run_json(capsys, "emva", "characterize", str(dataset), "--out", str(out), "--json", "--name", "cam")
    cpu = doc["provenance"]["cpu"]
    if Path("/proc/cpuinfo").exists():
        assert cpu in Path("/proc/cpuinfo").read_text()
    assert json.loads((out / "emva.json").read_text())["provenance"]["packages"]["numpy"] == np.__version__
    numpy_named = f"numpy {np.__version__}"
    for text in ((out / "datasheet.html").read_text(), (out / "cam.toml").read_text()):
        assert numpy_named in text and f"scipy {scipy.__version__}" in text and f"CPU {cpu}" in text
    made_with = ET.parse(out / "emva1288.xml").getroot().find("provenance")
    assert made_with.find("package[@name='numpy']").text == np.__version__ and made_with.find("cpu").text == cpu
    assert made_with.find("uwlab").text == uwlab.__version__


def test_general_model(dataset, tmp_path, capsys):
    out = tmp_path / "general"
    doc = run_json(capsys, "emva", "characterize", str(dataset), "--model", "general", "--out", str(out), "--json")
    assert doc["model"] == "general" and doc["K_dn_per_e"] is None
    assert doc["responsivity_dark_dn_per_photon"] == pytest.approx(0.3473 * 0.6, rel=0.03)
    names = {p.name for p in out.iterdir()}
    assert (
        "characteristic.png" in names
        and "photon_transfer.png" not in names
        and not any(n.endswith(".toml") for n in names)
    )
    assert any("no sensor profile written" in n for n in doc["notes"])
    # 40 linear steps from 3 ms start at SNR_p ≈ 20: no μ_p.min by interpolation (General D.1), said so
    assert doc["sensitivity_threshold_photons"] is None and any("D.1" in n for n in doc["notes"])
    root = ET.parse(out / "emva1288.xml").getroot()
    assert root.find("sensitivity/QE/Value").text == "nan" and root.find("sensitivity/sigma_d/Unit").text == "$p$"
    assert "N/A (cannot be measured)" in (out / "datasheet.html").read_text()


def test_summary_is_readable(dataset, capsys):
    assert main(["emva", "characterize", str(dataset)]) == 0
    out = capsys.readouterr().out
    assert "system gain K" in out and "DN/e-" in out and "±" in out and "Release 4.0 Linear" in out


def test_export_then_characterize_descriptor(dataset, tmp_path, capsys):
    desc_dir = tmp_path / "desc"
    doc = run_json(capsys, "emva", "export", str(dataset), "--out", str(desc_dir), "--image-size", "64x48", "--json")
    assert doc["synthetic_images"] is True
    a = run_json(capsys, "emva", "characterize", str(dataset), "--json")
    b = run_json(capsys, "emva", "characterize", "--descriptor", doc["descriptor"], "--json")
    assert b["K_dn_per_e"] == pytest.approx(a["K_dn_per_e"], rel=0.03)
    assert b["quantum_efficiency"] == pytest.approx(a["quantum_efficiency"], rel=0.03)


def test_fleet(dataset, tmp_path, capsys):
    """A folder of cameras: two datasets, one descriptor and one broken descriptor; one row each, the broken one
    refused with its reason, the others characterised; --out writes one directory per camera and the table."""
    fleet = tmp_path / "fleet"
    make_dataset(fleet / "cam-b", seed=9, prnu=2.0)
    shutil.copytree(dataset, fleet / "cam-a")
    assert main(["emva", "export", str(dataset), "--out", str(fleet / "cam-c"), "--image-size", "48x40"]) == 0
    (fleet / "cam-d").mkdir()
    (fleet / "cam-d" / "EMVA1288descriptor.txt").write_text("v 4.0\nn 64 8 8\n")
    capsys.readouterr()
    rows = run_json(capsys, "emva", "fleet", str(fleet), "--json")
    folders = [Path(r["source"]).name if Path(r["source"]).is_dir() else Path(r["source"]).parent.name for r in rows]
    assert folders == ["cam-a", "cam-b", "cam-c", "cam-d"]
    assert [r["status"] for r in rows] == ["ok", "ok", "ok", "refused"]
    assert "bits" in rows[3]["error"]
    assert rows[1]["prnu_percent"] == pytest.approx(2.0, rel=0.2)
    # the cameras in parallel on a real local Dask cluster: the same rows, in the same order
    assert run_json(capsys, "emva", "fleet", str(fleet), "--dask", "local", "--json") == rows
    assert main(["emva", "fleet", str(fleet), "--out", str(tmp_path / "out")]) == 0
    captured = capsys.readouterr()
    assert "3 of 4 cameras characterised" in captured.out and "refused" in captured.out
    out = tmp_path / "out"
    assert (out / "fleet.csv").read_text().count("\n") == 5
    assert (out / "cam-a" / "datasheet.html").exists() and (out / "cam-c" / "emva1288.xml").exists()


@pytest.mark.parametrize(
    "argv, words",
    [
        (["emva", "characterize"], "exactly one"),
        (["emva", "characterize", "/nonexistent/ds"], "not a dataset"),
        (["emva", "characterize", "--descriptor", "/nonexistent/d.txt"], "/nonexistent/d.txt"),
        (["emva", "characterize", "DS", "--irradiance", "0.5"], "--wavelength-nm"),
        (["emva", "characterize", "DS", "--irradiance", "-1"], "--irradiance"),
        (["emva", "characterize", "DS", "--sweep", "nope"], "--sweep"),
        (["emva", "fleet", "/nonexistent/folder"], "not a directory"),
    ],
)
def test_bad_input_is_one_line(dataset, capsys, argv, words):
    argv = [str(dataset) if a == "DS" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_shipped_plan_on_the_bench_measures_the_true_quantum_efficiency(tmp_path, capsys):
    """`uwlab sweep configs/plans/emva-photon-transfer.toml --sim` then `uwlab emva characterize`: η within 2 % of
    the simulated sensor's photon-weighted QE under the bench's light (issue 12: 46 % low with the water-side
    irradiance)."""
    data = tmp_path / "emva"
    assert (
        main(["sweep", str(ROOT / "configs" / "plans" / "emva-photon-transfer.toml"), "--sim", "--out", str(data)]) == 0
    )
    capsys.readouterr()
    doc = run_json(capsys, "emva", "characterize", str(data), "--json")
    truth = Dataset.open(data).metadata["sim_truth"]["photon-transfer"]
    assert doc["quantum_efficiency"] == pytest.approx(truth["quantum_efficiency"], rel=0.02)
    assert doc["K_dn_per_e"] == pytest.approx(truth["K_dn_per_e_output"], rel=0.02)
    assert doc["dark_current_e_per_s"] == pytest.approx(truth["dark_current_e_per_s"], rel=0.1)
    assert doc["dark_current_exposures"] >= 6


# The bench's photon-transfer and dark-current sweeps, their frames saved (`save_frames`).
FRAMES_PLAN = {
    "rig": ROOT / "configs" / "rigs" / "sim-emva-bench.toml",
    "camera": {"backend": "aravis", "id": "blackfly-s", "pixel_format": "Mono12", "window": [1200, 1000, 48, 40]},
    "instruments": {"light_port": "/dev/ttyUSB0", "spectrometer_port": "/dev/ttyUSB1"},
    "defaults": {
        "sensor": "imx250m",
        "lens": "none",
        "black_level_dn": 32,
        "frames_per_point": 2,
        "dark": "point",
        "dark_frames": 2,
        "save_frames": True,
    },
    "sweeps": [
        {
            "id": "photon-transfer",
            "kind": "exposure",
            "values": {"start": 20, "stop": 4600, "num": 16, "spacing": "linear"},
            "spectrometer": ["sensor"],
            "spectrometer_integration_ms": 10,
        },
        {
            "id": "dark-current",
            "kind": "dark",
            "values": {"start": 500000, "stop": 3000000, "num": 6, "spacing": "linear"},
            "dark": "none",
        },
    ],
}


def test_export_writes_the_recorded_frames(tmp_path, capsys):
    """A bench sweep with save_frames = true: `uwlab emva export` writes the camera's frames (ROI crops), not
    synthetic ones, so the descriptor gives back exactly the dataset's statistics."""
    from uwlab.experiments.emva.descriptor import photon_transfer_from_descriptor
    from uwlab.experiments.emva.from_dataset import load_dataset_input

    plan = write_plan(tmp_path / "plan.toml", "emva-frames", **FRAMES_PLAN)
    data = tmp_path / "data"
    assert main(["sweep", str(plan), "--sim", "--out", str(data)]) == 0
    capsys.readouterr()
    doc = run_json(capsys, "emva", "export", str(data), "--out", str(tmp_path / "desc"), "--json")
    assert doc["synthetic_images"] is False
    text = Path(doc["descriptor"]).read_text()
    assert "recorded frames" in text and "n 12 48 40" in text
    assert text.count("\nd ") == 16 + 6 and text.count("\nb ") == 16
    a = load_dataset_input(data).transfer.sorted()
    b = photon_transfer_from_descriptor(doc["descriptor"])
    np.testing.assert_allclose(b.mean_dn, a.mean_dn, rtol=1e-12)
    np.testing.assert_allclose(b.temporal_var_dn2, a.temporal_var_dn2, rtol=1e-12)
    np.testing.assert_allclose(b.dark_mean_dn, a.dark_mean_dn, rtol=1e-12)
    np.testing.assert_allclose(b.photons, a.photons, rtol=1e-8)
    assert len(b.dark) == 16 + 6
    # without frames the export says its images are synthetic
    assert main(["emva", "export", str(make_dataset(tmp_path / "plain")), "--out", str(tmp_path / "syn")]) == 0
    assert "SYNTHETIC images" in capsys.readouterr().out
