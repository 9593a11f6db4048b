"""DSNU and PRNU that a measurement does not give are printed as "—" with the reason beside them (or under the table),
in the summary of `uwlab emva characterize` and in the fleet table, as the datasheet gives it: a 16 × 16 px window
is smaller than the 19 px a side EMVA 1288 Release 4.0 §8.1's highpass filters need, so no spatial variance of the
nonuniformity is computed."""

import pytest

from uwlab.cli.main import main
from uwlab.experiments.emva.simulate import simulate_photon_transfer
from uwlab.model.sensor import load_sensor_profile
from uwlab.sim.devices.camera import SimTruth

REASON = "not computed: no highpassed spatial variances; record the sweep with a region of interest larger than 19 px"


@pytest.fixture(scope="module")
def small_window(tmp_path_factory):
    root = tmp_path_factory.mktemp("emva") / "pt"
    truth = SimTruth.from_sensor_profile(load_sensor_profile("imx250m"), resolution_px=(16, 16))
    simulate_photon_transfer(
        root,
        truth,
        rate_e_per_s=2e6,
        quantum_efficiency=0.6,
        exposures_us=[50 * i for i in range(1, 25)],
        dark_exposures_us=[1e5, 3e5],
    )
    return root


def test_the_summary_prints_the_reason_beside_the_dash(small_window, capsys):
    assert main(["emva", "characterize", str(small_window)]) == 0
    lines = capsys.readouterr().out.splitlines()
    for label in ("DSNU1288", "PRNU1288"):
        (line,) = [line for line in lines if line.strip().startswith(label)]
        assert line.split(label, 1)[1].strip().startswith(f"— ({REASON}")


def test_the_fleet_table_gives_the_reason_under_it(small_window, capsys):
    assert main(["emva", "fleet", str(small_window.parent)]) == 0
    out = capsys.readouterr().out
    (row,) = [line for line in out.splitlines() if line.startswith("SimCam-IMX250M")]
    assert row.split().count("—") == 2
    assert f"  — DSNU e-, PRNU % (SimCam-IMX250M): {REASON}" in out
