"""EMVA 1288 per colour channel (Release 4.0 Linear §1.2: each channel of a colour camera is a sensor of its own):
a raw Bayer sweep of the colour IMX250C on the simulated bench, characterised per channel by `uwlab emva characterize`,
recovers each channel's true system gain and quantum efficiency; a monochrome dataset with --channel is refused.

The truth is the simulation's (``metadata.sim_truth``: the camera's K and each channel's photon-weighted QE under the
bench's line, rendered from the profile's red/green/blue curves); the analysis reads neither the truth nor the
profile's QE curves.

Tolerances: the sweep's temporal variances come from frame pairs over a channel's sites of the 128 × 96 window,
P = 3072 (red, blue) or 6144 (green) per frame, each with a relative standard deviation sqrt(2/P) = 2.6 % (red,
blue) and 1.8 % (green); the K fit runs over the 20-odd points below 70 % of saturation, so its slope is good to
about 2.6 % × sqrt(3/20) ≈ 1 %: 3 % is three standard deviations. η = R/K adds R from the same points, whose
irradiance the simulated spectrometer reads to about 1 % per point (200 ms integration), so a few tenths of a
percent: 3 % covers both.
"""

import json
import shutil

import pytest

from uwlab.cli.main import main
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.emva.simulate import simulate_photon_transfer
from uwlab.model.sensor import load_sensor_profile
from uwlab.sim.devices.camera import SimTruth

from tests.support.paths import ROOT
from tests.support.plans import write_plan

CHANNELS = ("red", "green", "blue")
# The shipped bench (configs/rigs/sim-emva-bench.toml: a 525 nm line, the spectrometer at the sensor plane) with the
# colour IMX250C delivering raw RGGB frames; exposures to beyond the green channel's saturation.
COLOUR_PLAN = {
    "rig": ROOT / "configs" / "rigs" / "sim-emva-bench.toml",
    "camera": {"backend": "aravis", "id": "blackfly-s", "pixel_format": "BayerRG12", "window": [1160, 976, 128, 96]},
    "instruments": {"light_port": "/dev/ttyUSB0", "spectrometer_port": "/dev/ttyUSB1"},
    "defaults": {
        "sensor": "imx250c",
        "lens": "none",
        "black_level_dn": 32,
        "frames_per_point": 2,
        "dark": "point",
        "dark_frames": 2,
    },
    "sweeps": [
        {
            "id": "photon-transfer",
            "kind": "exposure",
            "values": {"start": 20, "stop": 4600, "num": 32, "spacing": "linear"},
            "spectrometer": ["sensor"],
            "spectrometer_integration_ms": 200,
        },
        {
            "id": "dark-current",
            "kind": "dark",
            "values": {"start": 500000, "stop": 3000000, "num": 4, "spacing": "linear"},
            "dark": "none",
        },
    ],
}


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# Fixed patterns the bench renders (the shipped profile has none): white DSNU and PRNU over every site.
DSNU_E, PRNU_PERCENT = 2.0, 1.0


def colour_profile(folder):
    """The shipped IMX250C profile with `DSNU_E` and `PRNU_PERCENT` (top-level keys go before its tables)."""
    shipped = ROOT / "configs" / "sensors" / "imx250c.toml"
    text = shipped.read_text().replace(
        "[provenance]", f"dsnu_e = {DSNU_E}\nprnu_percent = {PRNU_PERCENT}\n\n[provenance]", 1
    )
    shutil.copy(shipped.with_name("imx250c_qe.csv"), folder / "imx250c_qe.csv")
    (folder / "imx250c-patterned.toml").write_text(text)
    return folder / "imx250c-patterned.toml"


@pytest.fixture(scope="module")
def colour(tmp_path_factory):
    """The colour bench sweep's dataset and its ground truth."""
    folder = tmp_path_factory.mktemp("colour")
    profile = colour_profile(folder)
    plan = write_plan(
        folder / "plan.toml",
        "emva-colour",
        **COLOUR_PLAN | {"defaults": COLOUR_PLAN["defaults"] | {"sensor": str(profile)}},
    )
    data = folder / "data"
    assert main(["sweep", str(plan), "--sim", "--out", str(data)]) == 0
    return data, Dataset.open(data).metadata["sim_truth"]["photon-transfer"]


def test_each_channel_recovers_the_true_gain_and_its_own_quantum_efficiency(colour, capsys):
    data, truth = colour
    assert truth["quantum_efficiency_green"] > 3 * truth["quantum_efficiency_blue"]  # a 525 nm line: distinct QEs
    for channel in CHANNELS:
        code, out, _ = run(capsys, "emva", "characterize", str(data), "--channel", channel, "--json")
        assert code == 0
        doc = json.loads(out)
        assert doc["channel"] == channel
        assert doc["K_dn_per_e"] == pytest.approx(truth["K_dn_per_e_output"], rel=0.03), channel
        assert doc["quantum_efficiency"] == pytest.approx(truth[f"quantum_efficiency_{channel}"], rel=0.03), channel
        assert truth["dsnu_e"] == DSNU_E and truth["prnu_percent"] == PRNU_PERCENT
        assert doc["dsnu_e"] == pytest.approx(DSNU_E, rel=0.25), channel
        assert doc["prnu_percent"] == pytest.approx(PRNU_PERCENT, rel=0.25), channel


def test_only_the_green_channel_reaches_saturation_at_525_nm(colour, capsys):
    """Saturation is each channel's own: green clips (its full well, 10 700 e- in the profile, to within the sweep's
    step), red and blue never do and say that their saturation figures are lower bounds."""
    data, truth = colour
    code, out, _ = run(capsys, "emva", "characterize", str(data), "--json")
    assert code == 0
    docs = json.loads(out)["documents"]
    assert docs["green"]["saturation_e"] == pytest.approx(truth["saturation_e"], rel=0.1)
    assert not any("never reaches the clip level" in note for note in docs["green"]["notes"])
    for channel in ("red", "blue"):
        assert docs[channel]["saturation_e"] < 0.5 * truth["saturation_e"]
        assert any("never reaches the clip level in the " + channel in note for note in docs[channel]["notes"])


def test_without_channel_every_channel_gets_its_own_outputs(colour, capsys, tmp_path):
    data, truth = colour
    out = tmp_path / "result"
    code, text, _ = run(capsys, "emva", "characterize", str(data), "--out", str(out))
    assert code == 0
    assert "each colour channel a sensor of its own" in text
    summary = json.loads((out / "channels.json").read_text())
    assert list(summary["channels"]) == list(CHANNELS)
    for channel in CHANNELS:
        folder = out / channel
        assert (folder / "datasheet.html").exists() and (folder / "emva1288.xml").exists()
        doc = json.loads((folder / "emva.json").read_text())
        assert summary["channels"][channel]["K_dn_per_e"] == doc["K_dn_per_e"]
        sheet = (folder / "datasheet.html").read_text()
        assert f"{channel} channel" in sheet and "not computed for a colour channel" not in sheet  # DSNU, PRNU given
        profile = load_sensor_profile(str(folder / f"measured-simcam-imx250c-{channel}.toml"))
        assert profile.K_dn_per_e == pytest.approx(truth["K_dn_per_e"], rel=0.03)
    # nothing is overwritten: a second run is refused in one line
    code, _, err = run(capsys, "emva", "characterize", str(data), "--out", str(out))
    assert code == 2 and "exists" in err and len(err.strip().splitlines()) == 1


def test_the_python_api_takes_the_channel(colour):
    import uwlab
    from uwlab.errors import ConfigError

    data, truth = colour
    blue = uwlab.characterize(data, channel="blue")
    assert blue.quantum_efficiency == pytest.approx(truth["quantum_efficiency_blue"], rel=0.03)
    with pytest.raises(ConfigError, match="choose one of red, green, blue"):
        uwlab.characterize(data)


def test_a_monochrome_dataset_with_a_channel_is_refused_in_one_line(tmp_path, capsys):
    truth = SimTruth.from_sensor_profile(load_sensor_profile("imx250m"), resolution_px=(32, 32))
    root = tmp_path / "mono"
    simulate_photon_transfer(
        root, truth, rate_e_per_s=2e6, quantum_efficiency=0.6, exposures_us=[50 * i for i in range(1, 25)]
    )
    code, _, err = run(capsys, "emva", "characterize", str(root), "--channel", "red")
    assert code == 2
    assert "--channel" in err and "no per-channel statistics" in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
@pytest.mark.parametrize(("channel", "wavelength_nm"), [("red", 630.0), ("blue", 465.0)])
def test_a_channel_lit_by_its_own_line_saturates_and_recovers_its_quantum_efficiency(
    tmp_path, capsys, channel, wavelength_nm
):
    """The practice for a colour camera: each channel under a line its filter passes (the bench's LED changed), its
    photon transfer to its own saturation; K, η and the full well (the profile's 10 700 e-, within the sweep's
    steps) of that channel."""
    import tomllib

    import tomli_w

    rig = tomllib.loads((ROOT / "configs" / "rigs" / "sim-emva-bench.toml").read_text())
    rig["bench"]["wavelength_nm"] = wavelength_nm
    (tmp_path / "rig.toml").write_text(tomli_w.dumps(rig))
    sweeps = [dict(COLOUR_PLAN["sweeps"][0], values={"start": 20, "stop": 6000, "num": 32, "spacing": "linear"})]
    plan = write_plan(
        tmp_path / "plan.toml", "emva-colour-line", **{**COLOUR_PLAN, "rig": tmp_path / "rig.toml", "sweeps": sweeps}
    )
    data = tmp_path / "data"
    assert main(["sweep", str(plan), "--sim", "--out", str(data)]) == 0
    capsys.readouterr()
    truth = Dataset.open(data).metadata["sim_truth"]["photon-transfer"]
    code, out, _ = run(capsys, "emva", "characterize", str(data), "--channel", channel, "--json")
    assert code == 0
    doc = json.loads(out)
    assert doc["K_dn_per_e"] == pytest.approx(truth["K_dn_per_e_output"], rel=0.03)
    assert doc["quantum_efficiency"] == pytest.approx(truth[f"quantum_efficiency_{channel}"], rel=0.03)
    assert doc["saturation_e"] == pytest.approx(truth["saturation_e"], rel=0.1)
    assert not any("never reaches the clip level" in note for note in doc["notes"])


def test_a_fleet_gives_a_colour_camera_a_row_per_channel(colour, capsys, tmp_path):
    data, truth = colour
    code, out, _ = run(capsys, "emva", "fleet", str(data.parent), "--out", str(tmp_path / "fleet"), "--json")
    assert code == 0
    rows = json.loads(out)
    assert [row["camera"] for row in rows] == [f"SimCam-IMX250C-{channel}" for channel in CHANNELS]
    for channel, row in zip(CHANNELS, rows, strict=True):
        assert row["quantum_efficiency"] == pytest.approx(truth[f"quantum_efficiency_{channel}"], rel=0.03)
        assert (tmp_path / "fleet" / "data" / channel / "datasheet.html").exists()
