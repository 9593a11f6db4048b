"""Colour sweeps on the simulated rig: per-channel columns against the design model's per-channel prediction, mono
points without them, and a plan whose declared Bayer layout the camera does not deliver refused before anything
is recorded.

Truth: the design model (`uwlab.model.evaluation.evaluate`) with ``sensor.channel`` = red, green or blue predicts
each channel's dark-subtracted mean from the colour profile (its QE column, K, bit depth); the simulated camera
renders each Bayer site from the rig's own scene. The one world truth the model lacks is the light's true flux
over its rated flux (the rig's ``[sim] light_efficiency``, recorded in ``sim_truth``), which a fit recovers; the
ratios between channels do not depend on it.
"""

from __future__ import annotations

import numpy as np
import pytest

from uwlab.cli.main import main
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.calibration.forward import build_forward_model
from uwlab.experiments.dataset import CHANNEL_FIELDS, Dataset, channel_view
from uwlab.experiments.frames.frame import CHANNEL_NAMES
from uwlab.model.evaluation import evaluate

from tests.support.plans import record, write_plan

EXPOSURES_US = [100.0, 200.0, 400.0]
# a 64 × 48 px window at the centre of the IMX250's 2448 × 2048 pixels (on the board)
WINDOW = [1192, 1000, 64, 48]
COLOUR = {
    "id": "colour",
    "kind": "exposure",
    "values": EXPOSURES_US,
    "sensor": "imx250c",
    "camera": {"pixel_format": "BayerRG12", "window": WINDOW, "bayer": "RG"},
}
MONO = {
    "id": "mono",
    "kind": "exposure",
    "values": [200.0],
    "sensor": "imx250m",
    "camera": {"pixel_format": "Mono12", "window": WINDOW},
}


def model_signal_dn(design, channel: str, exposure_us: float) -> float:
    """The design model's dark-subtracted mean of ``channel`` at ``exposure_us`` on the rig's design."""
    d = design.with_values(**{"sensor.channel": channel, "operation.exposure_s": exposure_us * 1e-6})
    return float(evaluate(d)["mean_dn"]) - float(d.sensor.dark_dn(d["sensor.bit_depth"] or d.sensor.bit_depth))


@pytest.fixture(scope="module")
def colour_sweep(tmp_path_factory, sim_rig):
    tmp = tmp_path_factory.mktemp("colour")
    plan = load_plan(
        write_plan(tmp / "plan.toml", "colour", [COLOUR, MONO], defaults={"black_level_dn": 32, "frames_per_point": 4})
    )
    return plan, record(plan, tmp / "data", sim_rig)


def test_each_channel_signal_is_the_models_per_channel_prediction(colour_sweep):
    plan, data = colour_sweep
    points = data.points().set_index("sweep_id").loc["colour"]
    design = plan.sweeps[0].design
    efficiency = data.metadata["sim_truth"]["colour"]["light_efficiency"]
    assert not points["saturated"].any() and (points["bayer"] == "RG").all()
    differences = {}
    for channel in CHANNEL_NAMES.values():
        measured = points[f"{channel}_signal_dn"].to_numpy(float)
        predicted = np.array([efficiency * model_signal_dn(design, channel, t) for t in EXPOSURES_US])
        differences[channel] = measured / predicted - 1
        assert not points[f"{channel}_saturated"].any()
    print({channel: [f"{100 * d:+.2f} %" for d in diff] for channel, diff in differences.items()})
    for channel, diff in differences.items():
        assert np.abs(diff).max() < 0.02, channel
    # the colour balance needs no world truth at all: each channel's share of the green
    green = points["green_signal_dn"].to_numpy(float)
    for channel in ("red", "blue"):
        measured = points[f"{channel}_signal_dn"].to_numpy(float) / green
        predicted = [model_signal_dn(design, channel, t) / model_signal_dn(design, "green", t) for t in EXPOSURES_US]
        np.testing.assert_allclose(measured, predicted, rtol=0.02)


def test_a_bare_colour_sensor_reads_each_channel_through_its_own_qe(tmp_path, sim_rig):
    """No lens: each channel's signal is the model's per-channel prediction too (a bare sensor rendered with the
    combined QE read red +73 %, green −27 %, blue +39 %)."""
    bare = {**COLOUR, "id": "bare", "lens": "none", "values": [100.0], "light_level": 0.2}
    plan = load_plan(write_plan(tmp_path / "plan.toml", "bare", [bare], defaults={"black_level_dn": 32}))
    data = record(plan, tmp_path / "data", sim_rig)
    (point,) = data.points().itertuples()
    efficiency = data.metadata["sim_truth"]["bare"]["light_efficiency"]
    flux = 0.2 ** data.metadata["sim_truth"]["bare"]["light_gamma"]
    design = plan.sweeps[0].design
    for channel in CHANNEL_NAMES.values():
        predicted = efficiency * model_signal_dn(design, channel, 100.0 * flux)  # at full light it would saturate
        print(channel, f"{100 * (getattr(point, f'{channel}_signal_dn') / predicted - 1):+.2f} %")
        assert getattr(point, f"{channel}_signal_dn") / predicted == pytest.approx(1.0, abs=0.02), channel


def test_each_channel_follows_the_photon_transfer_of_the_one_system_gain(colour_sweep):
    """EMVA 1288 Release 4.0 Linear eq. 6 per channel: σ²_y − σ²_y.dark = K (μ_y − μ_y.dark), one K for all three
    (the colour filters change the photons, not the pixel's conversion)."""
    _, data = colour_sweep
    points = data.points().set_index("sweep_id").loc["colour"]
    k = data.metadata["sim_truth"]["colour"]["K_dn_per_e_output"]
    for channel in CHANNEL_NAMES.values():
        noise = points[f"{channel}_temporal_var_dn2"] - points[f"{channel}_dark_temporal_var_dn2"]
        np.testing.assert_allclose(noise, k * points[f"{channel}_signal_dn"], rtol=0.1, err_msg=channel)
        assert (points[f"{channel}_pixels"] == 64 * 48 // 4 * (2 if channel == "green" else 1)).all()
    # the mosaic is its channels pooled, site for site
    pooled = sum(points[f"{c}_mean_dn"] * points[f"{c}_pixels"] for c in CHANNEL_NAMES.values()) / (64 * 48)
    np.testing.assert_allclose(points["mean_dn"], pooled, rtol=1e-12)


def test_a_mono_point_has_no_channel_columns(colour_sweep):
    _, data = colour_sweep
    mono = data.points().set_index("sweep_id").loc[["mono"]]
    assert mono["bayer"].isna().all()
    assert all(mono[name].isna().all() for name, _ in CHANNEL_FIELDS)
    with pytest.raises(ConfigError, match="sweeps mono have no per-channel columns"):
        channel_view(data.points(), "red")


def test_the_fits_forward_model_predicts_each_channel_with_its_own_qe(colour_sweep):
    """The fit's forward model (`uwlab.experiments.calibration.forward`) at the nominal parameters and the rig's true
    light efficiency predicts each channel's points within 2 %; the mosaic's combined QE would miss red and blue by
    far more."""
    _, data = colour_sweep
    points = data.points()
    points = points[points["sweep_id"] == "colour"].reset_index(drop=True)
    efficiency = data.metadata["sim_truth"]["colour"]["light_efficiency"]
    predictions = {}
    for channel in CHANNEL_NAMES.values():
        view = channel_view(points, channel)
        model = build_forward_model(view, data.metadata["rigs"], ("light_efficiency",))
        predictions[channel] = model.predict(np.array([[efficiency]]))[0]
        difference = view["signal_dn"].to_numpy(float) / predictions[channel] - 1
        print(channel, [f"{100 * d:+.2f} %" for d in difference])
        assert np.abs(difference).max() < 0.02, channel
    mosaic = build_forward_model(points, data.metadata["rigs"], ("light_efficiency",)).predict(np.array([[efficiency]]))
    np.testing.assert_allclose(mosaic[0], points["signal_dn"], rtol=0.02)  # the mosaic with the combined QE
    assert abs(predictions["red"] / mosaic[0] - 1).min() > 0.2 and abs(predictions["blue"] / mosaic[0] - 1).min() > 0.2


COLOUR_CAMERA = {"pixel_format": "BayerRG12", "window": WINDOW}
MONO_CAMERA = {"pixel_format": "Mono12", "window": WINDOW}


@pytest.mark.parametrize(
    ("plan_camera", "first_camera", "second_camera", "shown", "device"),
    [
        # the plan's [camera] layout, for every sweep
        ({"bayer": "GB"}, COLOUR_CAMERA, COLOUR_CAMERA, "error: camera.bayer = 'GB'", "BayerRG12 is Bayer RG"),
        # only the second sweep's camera (monochrome) is wrong: the first, fine, is not measured either
        ({}, COLOUR_CAMERA, {**MONO_CAMERA, "bayer": "RG"}, "sweep.second.camera.bayer = 'RG'", "Mono12 is monochrome"),
    ],
)
def test_a_bayer_layout_the_camera_does_not_deliver_is_refused_before_anything_is_recorded(
    tmp_path, capsys, plan_camera, first_camera, second_camera, shown, device
):
    sweeps = [
        {"id": "first", "kind": "exposure", "values": [100.0], "sensor": "imx250c", "camera": first_camera},
        {
            "id": "second",
            "kind": "exposure",
            "values": [100.0],
            "sensor": "imx250c" if "Bayer" in second_camera["pixel_format"] else "imx250m",
            "camera": second_camera,
        },
    ]
    plan = write_plan(tmp_path / "plan.toml", "refused", sweeps, camera=plan_camera or None)
    out = tmp_path / "data"
    assert main(["sweep", str(plan), "--sim", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and shown in err and device in err, err
    assert Dataset.open(out).points().empty


def test_a_fit_of_one_channel_recovers_the_light_from_that_channels_qe(tmp_path, sim_rig):
    """``uwlab.fit(..., channel="red")`` on a two-lens colour campaign: the light efficiency (the rig's truth, which
    the fit never sees) is recovered from the red sites alone; predicting them with the mosaic's combined QE would
    put it near 0.46."""
    import uwlab

    lenses = [
        {"focal_length_mm": 30, "f_number": 2.0, "f_number_range": [2.0, 16.0]},
        {"focal_length_mm": 12, "f_number": 4.0, "f_number_range": [1.4, 16.0]},
    ]
    sweeps = [
        {
            "id": f"lens{i}",
            "kind": "exposure",
            "values": {"start": 50 * (4 if i else 1), "stop": 600 * (4 if i else 1), "num": 8},
            "sensor": "imx250c",
            "lens": lens,
            "camera": {"pixel_format": "BayerRG12", "window": WINDOW, "bayer": "RG"},
        }
        for i, lens in enumerate(lenses)
    ]
    plan = load_plan(write_plan(tmp_path / "plan.toml", "campaign", sweeps, defaults={"frames_per_point": 2}))
    data = record(plan, tmp_path / "data", sim_rig)
    fit = uwlab.fit(tmp_path / "data", "paper", channel="red", progress=False, max_steps=1000, chunk_steps=500)
    assert fit.summary["channel"] == "red"
    efficiency = fit.parameters.loc["light_efficiency"]
    truth = data.metadata["sim_truth"]["lens0"]["light_efficiency"]
    assert efficiency["p2_5"] < truth < efficiency["p97_5"]
    assert efficiency["median"] == pytest.approx(truth, rel=0.05)
    # the red sites read with the combined QE: 0.8 × (red signal / mosaic signal) ≈ 0.46, outside the 95 % interval
    assert efficiency["p2_5"] > 0.55


def test_fitting_a_channel_of_monochrome_points_is_refused_in_one_line(colour_sweep, capsys, tmp_path):
    _, data = colour_sweep
    assert main(["fit", str(data.root), "--channel", "red", "--out", str(tmp_path / "fit")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--channel = 'red': sweeps mono have no per-channel columns" in err, err
    assert not (tmp_path / "fit").exists()
