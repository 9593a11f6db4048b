"""A colour tank campaign fitted one channel at a time (issue 32): on the simulated tank with the colour IMX250C
(configs/rigs/sim-tank-colour.toml), no lens, 30 mm F2.0 and 12 mm F4.0, `uwlab.fit(..., channel=C)` for red, green
and blue. The truth the fit never sees: the rig's ``[sim] light_efficiency`` (0.8), recorded in the dataset's
``sim_truth``. Each channel's 95 % interval must cover it, and the bare sensor — held out, predicted from the two
lenses — must read as its channel's QE predicts (a bare sensor rendered with the combined QE, grey, was +73 % off in
red)."""

from __future__ import annotations

import pytest

import uwlab
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.sim_rig import SimRig

from tests.support.paths import CONFIGS
from tests.support.plans import record, write_plan

RIG = CONFIGS / "rigs" / "sim-tank-colour.toml"
CAMERA = {"pixel_format": "BayerRG12", "window": [1192, 1000, 32, 24], "bayer": "RG"}
# light levels as in configs/plans/tank-exposure-sweep.toml: the bare sensor and the F2.0 lens dimmed
SWEEPS = [
    {"id": "imx250c-no-lens", "lens": "none", "light_level": 0.2},
    {"id": "imx250c-30mm-f2", "lens": {"focal_length_mm": 30, "f_number": 2.0, "f_number_range": [2.0, 16.0]}},
    {"id": "imx250c-12mm-f4", "lens": {"focal_length_mm": 12, "f_number": 4.0, "f_number_range": [1.4, 16.0]}},
]
SWEEPS[1]["light_level"] = 0.35
DEFAULTS = {
    "kind": "exposure",
    "values": {"start": 20, "stop": 1500, "num": 6, "spacing": "log"},
    "sensor": "imx250c",
    "camera": CAMERA,
    "frames_per_point": 2,
    "dark": "point",
    "dark_frames": 2,
    "black_level_dn": 32,  # dark frames above zero, not clipped
    "spectrometer": ["target", "camera"],
    "spectrometer_integration_ms": 10,
}
TRAIN = ["imx250c-30mm-f2", "imx250c-12mm-f4"]


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("colour-campaign")
    plan = load_plan(write_plan(tmp / "plan.toml", "colour-campaign", SWEEPS, rig=RIG, defaults=DEFAULTS))
    with SimRig(RIG) as rig:
        data = record(plan, tmp / "data", rig)
    return tmp, data


@pytest.mark.slow
@pytest.mark.parametrize("channel", ["red", "green", "blue"])
def test_each_channels_light_efficiency_interval_covers_the_truth(campaign, channel):
    tmp, data = campaign
    truth = {sweep["id"]: data.metadata["sim_truth"][sweep["id"]]["light_efficiency"] for sweep in SWEEPS}
    assert set(truth.values()) == {0.8}
    assert not data.points()[f"{channel}_saturated"].any()
    fit = uwlab.fit(
        data.root, None, tmp / f"fit-{channel}", train=TRAIN, channel=channel, progress=False, max_steps=1500
    )
    assert fit.summary["channel"] == channel
    efficiency = fit.parameters.loc["light_efficiency"]
    print(channel, efficiency[["p2_5", "median", "p97_5"]].round(3).to_dict())
    assert efficiency["p2_5"] < 0.8 < efficiency["p97_5"]
    assert efficiency["median"] == pytest.approx(0.8, rel=0.05)  # grey: red 1.04, green 0.74, blue 0.92
    (bare,) = [c for c in fit.summary["cross_configuration"] if c["sweep_id"] == "imx250c-no-lens"]
    print(channel, "held-out bare sensor", f"{bare['level_offset_percent']:+.1f} %")
    assert bare["role"] == "held out" and abs(bare["level_offset_percent"]) < 3.0
