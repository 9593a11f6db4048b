"""The lens groups of the calibration model: a lens setting's transmittance is shared by the cameras that carry it,
the bare sensor's factor by the bare sensors, so that a held-out configuration is predicted from its lens sibling on
the other camera (docs/validation.md, "The lens groups")."""

import numpy as np
import pytest

from uwlab.errors import ConfigError
from uwlab.experiments.calibration.fit import default_config_for
from uwlab.experiments.calibration.forward import build_forward_model
from uwlab.experiments.calibration.priors import HalfNormal
from uwlab.experiments.calibration.simulate import simulate_campaign
from uwlab.experiments.calibration.validation import held_out_fold
from uwlab.model.optics import NO_LENS, LensSetting

LENS = LensSetting(30.0, 2.0)
# The true lens passes 0.80 where the design says 0.90: a lens-group offset of −11 % that the chain cannot know
TRUTH = {"light_efficiency": 0.8, "lens_transmittance": 0.80, "K_dn_per_e:imx250m": 0.36, "K_dn_per_e:icx285alm": 1.05}


@pytest.fixture(scope="module")
def campaign():
    return simulate_campaign(TRUTH, lenses=(NO_LENS, LENS), points_per_sweep=8, seed=5)


def test_a_held_out_lens_is_predicted_from_its_sibling_on_the_other_camera(campaign):
    """imx250m with the 30 mm lens, held out, is predicted from icx285alm with the same lens (and imx250m's bare
    sensor for its K): its level is the truth's to within 1 % although the design's lens is 11 % off, and its 95 %
    band holds its points."""
    points, rigs = campaign
    config = default_config_for(points[~points["saturated"]], rigs)
    assert f"lens_transmittance:{LENS.label}" in config.priors and "bare_sensor_factor" in config.priors
    fold = held_out_fold(points, rigs, config, [f"imx250m-{LENS.label}"], 0)
    assert fold is not None
    row = fold.table.iloc[0]
    assert row["median_abs_rel_error"] < 0.01
    assert row["inside_95"] >= 0.9
    # without the lens groups (one spread τ for everything, as before) the sibling's −11 % is one offset among
    # three and the held-out level misses by several per cent
    plain = {n: p for n, p in config.priors.items() if not n.startswith(("lens_transmittance", "bare_sensor"))}
    plain["config_discrepancy"] = HalfNormal(sigma=0.05)
    without = held_out_fold(points, rigs, config.model_copy(update={"priors": plain}), [f"imx250m-{LENS.label}"], 0)
    assert without is not None and without.table.iloc[0]["median_abs_rel_error"] > 0.03


def test_lens_group_parameters_scale_their_group_alone(campaign):
    """A lens setting's transmittance scales that lens's configurations on both cameras and nothing else; the bare
    sensor's factor scales the bare sensors alone."""
    points, rigs = campaign
    names = (f"lens_transmittance:{LENS.label}", "bare_sensor_factor")
    model = build_forward_model(points, rigs, names)
    t0 = model.nominal[names[0]]
    base = model.predict(np.array([[t0, 1.0]]))[0]
    scaled = model.predict(np.array([[0.5 * t0, 1.1]]))[0]
    bare = points["f_number"].isna().to_numpy()
    assert scaled[~bare] == pytest.approx(0.5 * base[~bare], rel=1e-12)
    assert scaled[bare] == pytest.approx(1.1 * base[bare], rel=1e-12)
    assert set(points.loc[~bare, "sensor_profile"]) == {"imx250m", "icx285alm"}


def test_lens_group_parameters_need_their_configurations(campaign):
    points, rigs = campaign
    lensed = points[points["f_number"].notna()]
    with pytest.raises(ConfigError, match="parameters.bare_sensor_factor"):
        build_forward_model(lensed, rigs, ("bare_sensor_factor",))
    with pytest.raises(ConfigError, match="parameters.lens_transmittance:12mm-F4.0"):
        build_forward_model(points, rigs, ("lens_transmittance:12mm-F4.0",))
    with pytest.raises(ConfigError, match="parameters.lens_transmittance"):
        build_forward_model(points, rigs, ("lens_transmittance", f"lens_transmittance:{LENS.label}"))
