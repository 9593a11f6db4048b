"""The demo's targets on a reduced campaign (in process, `uwlab.experiments.demo.quick_demo`; the full demo over
ten seeds is benchmarks/demo_targets.py, the bands' sharpness over ten seeds benchmarks/held_out_bands.py): the
extended model in the tank world predicts held-out configurations to about 0.1 % from their lens siblings, inside
their bands, and covers the simulated truths (only the trend check may name the tank
world's unmodelled sensor non-linearity); the paper model in the turbid world is judged inadequate with
backscatter named; the paper model in the ideal world (the model against itself) is adequate.

The tank world's targets are held by each of three seeds on its own (a test per seed, so that none runs for
minutes), with the demo's folds (leave one configuration out). The turbid and the ideal world's verdicts are judged
with two held-out folds of three configurations each (3 fits instead of 7): the verdict's checks are the same, and
predicting three configurations from the other three asks more of the model than predicting one from five."""

import pytest

from uwlab.experiments.demo import quick_demo, target_tally


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(3))
def test_extended_model_in_the_tank_world_meets_the_targets(seed):
    summary = quick_demo("tank", "extended", seed)
    tally = target_tally([summary])
    assert tally["held_out_inside_95"] >= 0.90, tally
    assert tally["truth_inside_95"] >= 0.90, tally
    # Each configuration predicted from the five others (leave one out) with its lens sibling's transmittance (or
    # the bare sensors' factor): median errors about 0.1 % (0.9 % with one spread τ for every configuration). The
    # bands are not asserted sharp: five configurations leave one degree of freedom for τ after the camera × lens
    # table, so each fold's τ is mostly its prior's and the bands are ±3 % (docs/validation.md).
    assert tally["held_out_error_percent_median_range"][2] <= 0.3, tally
    # every check passes but, where it fires, the trend check: the tank world's sensor non-linearity, unmodelled
    failed = {check["name"] for check in summary["checks"] if not check["passed"]}
    assert failed <= {"within-configuration trend"}, summary["checks"]


@pytest.mark.slow
def test_paper_model_in_the_turbid_world_is_inadequate_and_names_backscatter():
    summary = quick_demo("turbid", "paper", seed=0, held_out=2)
    assert not summary["model_adequate"]
    assert any("backscatter" in w for w in summary["warnings"]), summary["warnings"]


@pytest.mark.slow
def test_paper_model_in_the_ideal_world_is_adequate():
    tally = target_tally([quick_demo("ideal", "paper", seed=0, held_out=2)])
    assert tally["adequate"] == 1 and tally["truth_inside_95"] == 1.0, tally
