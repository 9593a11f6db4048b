"""Sweeps on the simulated rig (serial light and spectrometer on pseudo-terminals, in-process camera):
statistics against the EMVA 1288 model, the light path, apertures, device loss, disk full, resume."""

import errno

import numpy as np
import pytest

from uwlab.sim.devices.camera import SimFaults
from uwlab.errors import ConfigError
from uwlab.experiments import dataset_store
from uwlab.experiments.dataset import Dataset, DatasetWriteError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.rigs import HardwareRig
from uwlab.experiments.acquisition.sweep import SweepRunner, check_resumable, open_for_resume

from tests.support.plans import camera, record, write_plan

EXPOSURE = {
    "id": "exposure",
    "kind": "exposure",
    "values": [50, 100, 200, 300, 400],
    "spectrometer": ["target", "camera"],
}


def plan_file(path, *sweeps: dict):
    return write_plan(
        path, "sim-unit", sweeps, camera=camera(64, 48), defaults={"black_level_dn": 32, "frames_per_point": 4}
    )


def run(tmp_path, rig, *sweeps: dict, name="d"):
    plan = load_plan(plan_file(tmp_path / f"{name}.toml", *sweeps))
    return plan, record(plan, tmp_path / name, rig)


def test_exposure_sweep_agrees_with_the_emva_model(tmp_path, sim_rig):
    _, data = run(tmp_path, sim_rig, EXPOSURE)
    points = data.points()
    truth = data.metadata["sim_truth"]["exposure"]
    k = truth["K_dn_per_e_output"]
    signal = points["signal_dn"].to_numpy()
    exposure = points["exposure_us"].to_numpy()
    assert not points["saturated"].any()
    slope = np.sum(signal * exposure) / np.sum(exposure**2)
    np.testing.assert_allclose(signal, slope * exposure, rtol=0.02)  # mean signal ∝ exposure
    expected_slope = k * truth["window_mean_rate_e_per_s"] * 1e-6
    assert slope == pytest.approx(expected_slope, rel=0.03)
    # photon transfer: σ²_y = K·μ_signal + σ²_dark (EMVA 1288 eq. 6); 4 frames x 3072 px per point
    predicted = k * signal + points["dark_temporal_var_dn2"].to_numpy()
    np.testing.assert_allclose(points["temporal_var_dn2"], predicted, rtol=0.08)
    dark_var = (truth["dark_noise_e"] * k) ** 2 + 1 / 12
    assert points["dark_temporal_var_dn2"].mean() == pytest.approx(dark_var, rel=0.15)
    assert points["dark_mean_dn"].mean() == pytest.approx(32, abs=0.5)
    # spectra at both positions; the point's irradiance is the first position's (target)
    spectra = data.spectra()
    assert set(spectra["position"]) == {"target", "camera"} and len(spectra) == 2 * 5 * 401
    assert (points["irradiance_position"] == "target").all() and (points["irradiance_w_m2"] > 0).all()
    assert data.metadata["devices"]["exposure"]["light"].startswith("UWLAB,SIM-LIGHT")
    assert data.metadata["rigs"]["exposure"]["sensor"]["profile"] == "imx250m"
    assert data.metadata["finished_utc"] is not None


def test_saturation_is_flagged(tmp_path, sim_rig):
    _, data = run(tmp_path, sim_rig, {"id": "s", "kind": "exposure", "values": [100, 5000]})
    points = data.points()
    assert points["saturated"].tolist() == [False, True]
    assert points["saturated_fraction"].iloc[1] > 0.9


def test_light_level_sweep_dims_the_images_through_the_serial_light(tmp_path, sim_rig):
    _, data = run(tmp_path, sim_rig, {"id": "l", "kind": "light-level", "values": [0.25, 0.5, 1.0], "exposure_us": 300})
    points = data.points()
    gamma = data.metadata["sim_truth"]["l"]["light_gamma"]
    ratios = points["signal_dn"].to_numpy() / points["signal_dn"].iloc[-1]
    np.testing.assert_allclose(ratios, np.array([0.25, 0.5, 1.0]) ** gamma, rtol=0.03)
    assert points["light_level"].tolist() == [0.25, 0.5, 1.0]


def test_aperture_sweep_follows_the_inverse_square_of_the_f_number(tmp_path, sim_rig):
    _, data = run(
        tmp_path,
        sim_rig,
        {
            "id": "a",
            "kind": "aperture",
            "values": [4.0, 8.0],
            "exposure_us": 2000,
            "dark": "block",
            "roi": "aruco",
            "lens": {"focal_length_mm": 12, "f_number": 4.0, "f_number_range": [1.4, 16]},
        },
    )
    points = data.points()
    assert points["signal_dn"].iloc[1] / points["signal_dn"].iloc[0] == pytest.approx(0.25, rel=0.03)
    assert points["lens_label"].tolist() == ["12mm-F4.0", "12mm-F8.0"]
    assert points["roi_w"].iloc[0] == 64  # the board covers the whole window


def test_device_lost_mid_sweep_reconnects_and_completes(tmp_path, sim_rig, monkeypatch):
    cameras = []
    original = sim_rig.open_camera

    def open_and_keep(sweep):
        camera = original(sweep)
        cameras.append(camera)
        return camera

    monkeypatch.setattr(sim_rig, "faults", SimFaults(lost_after=7, failed_reconnects=1))
    monkeypatch.setattr(sim_rig, "open_camera", open_and_keep)
    _, data = run(tmp_path, sim_rig, {"id": "e", "kind": "exposure", "values": [100, 200, 300]})
    assert cameras[0].stats.reconnects == 1
    points = data.points()
    assert len(points) == 3 and (points["exposure_us_readback"] == points["exposure_us"]).all()
    np.testing.assert_allclose(
        points["signal_dn"] / points["exposure_us"], points["signal_dn"].iloc[0] / 100, rtol=0.02
    )


def test_disk_full_keeps_the_points_and_resume_completes(tmp_path, sim_rig, monkeypatch):
    plan = load_plan(
        plan_file(tmp_path / "p.toml", {"id": "e", "kind": "exposure", "values": [100, 200, 300, 400], "dark": "none"})
    )
    data = Dataset.create(tmp_path / "d", plan.raw, plan_sha256=plan.sha256, sim=True)
    parts = []
    real_write = dataset_store.write_durable

    def fill_up(where, payload):
        if where.parent.name == "parts":
            parts.append(where)
            if len(parts) > 2:
                raise OSError(errno.ENOSPC, "No space left on device")
        real_write(where, payload)

    monkeypatch.setattr(dataset_store, "write_durable", fill_up)
    with pytest.raises(DatasetWriteError, match="No space left on device.*--resume"):
        SweepRunner(plan, data, sim_rig).run()
    monkeypatch.undo()
    data.close()
    assert Dataset.open(tmp_path / "d").completed() == {("e", 0), ("e", 1)}
    started_with = Dataset.open(tmp_path / "d").metadata["provenance"]
    with open_for_resume(tmp_path / "d", plan, sim=True) as resumed:
        SweepRunner(plan, resumed, sim_rig).run()
    assert sorted(Dataset.open(tmp_path / "d").points()["point_index"]) == [0, 1, 2, 3]
    # the machine and versions that started it stay; the resuming session's are added beside them
    metadata = Dataset.open(tmp_path / "d").metadata
    assert metadata["provenance"] == started_with and len(metadata["resumed"]) == 1
    assert metadata["resumed"][0]["provenance"]["packages"]["numpy"] == np.__version__


def test_foreign_dataset_is_refused(tmp_path, sim_rig):
    plan, data = run(tmp_path, sim_rig, {"id": "e", "kind": "exposure", "values": [100], "dark": "none"})
    other = plan_file(tmp_path / "other.toml", {"id": "e", "kind": "exposure", "values": [100, 200], "dark": "none"})
    with pytest.raises(ConfigError, match="different plan"):
        check_resumable(data, load_plan(other), sim=True)
    with pytest.raises(ConfigError, match="simulated rig"):
        check_resumable(data, plan, sim=False)


def test_manual_aperture_prompts_the_operator_or_refuses(tmp_path):
    manual = {
        "id": "a",
        "kind": "aperture",
        "values": [4.0, 8.0],
        "dark": "none",
        "lens": {"focal_length_mm": 12, "f_number": 4.0},
    }
    plan = load_plan(plan_file(tmp_path / "hw.toml", manual))
    data = Dataset.create(tmp_path / "d", plan.raw, plan_sha256=plan.sha256)
    with HardwareRig(plan, confirm=None) as rig, pytest.raises(ConfigError, match="--non-interactive"):
        SweepRunner(plan, data, rig).run()
    prompts = []
    with HardwareRig(plan, confirm=prompts.append) as rig:
        SweepRunner(plan, data, rig).run()
    assert prompts == ["set the 12 mm lens to F4", "set the 12 mm lens to F8"]
    assert Dataset.open(tmp_path / "d").points()["f_number"].tolist() == [4.0, 8.0]
