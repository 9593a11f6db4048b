"""`uwlab.sweep` on the simulated rig (simulators on pseudo-terminals): the dataset it returns, resuming a complete
one measures nothing, and with stderr not a terminal no progress is written."""

import pytest

import uwlab
from uwlab.errors import ConfigError
from tests.support.plans import write_campaign


def test_sweep_resume_and_quiet_progress(tmp_path, capfd):
    plan = write_campaign(
        tmp_path / "plan.toml", "api-small", sweeps=1, values={"start": 50, "stop": 800, "num": 3, "spacing": "log"}
    )
    data = uwlab.sweep(plan, tmp_path / "data", sim=True, seed=2)
    assert isinstance(data, uwlab.Dataset)
    assert data.points["exposure_us"].tolist() == pytest.approx([50, 200, 800], rel=1e-6)
    assert data.summary["state"] == "complete"
    assert set(data.spectra["position"]) == {"target", "camera"}
    again = uwlab.sweep(plan, tmp_path / "data", sim=True, resume=True)
    assert again.points.equals(data.points)
    assert capfd.readouterr().err == ""  # stderr is not a terminal here: no bar, no escape codes
    with pytest.raises(ConfigError, match="exists"):
        uwlab.sweep(plan, tmp_path / "data", sim=True)
