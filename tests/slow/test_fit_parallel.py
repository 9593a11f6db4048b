"""Held-out folds in parallel (`uwlab.experiments.calibration.parallel`): a script without an
``if __name__ == "__main__"`` guard runs its folds in worker processes without being run again by them, and the
workers' predictions are those of the same folds fitted in process, number for number; a fold's error reaches the
caller as one line."""

import json
import subprocess
import sys
import textwrap

import pytest

from uwlab.errors import UwlabError
from uwlab.experiments.calibration.fit import default_config_for
from uwlab.experiments.calibration.parallel import FoldJob, folds_in_background
from uwlab.experiments.calibration.simulate import simulate_campaign

# No __main__ guard on purpose: a multiprocessing spawn/forkserver child would import it again and append a line.
SCRIPT = textwrap.dedent(
    """
    import json, sys
    from pathlib import Path

    with Path(sys.argv[1]).open("a") as log:
        log.write("ran\\n")

    from uwlab.experiments.calibration.fit import Sampler, default_config_for
    from uwlab.experiments.calibration.parallel import FoldJob, folds_in_background, run_folds
    from uwlab.experiments.calibration.simulate import simulate_campaign
    from uwlab.experiments.calibration.validation import default_folds

    points, rigs = simulate_campaign({"light_efficiency": 0.8}, seed=3, points_per_sweep=8)
    config = default_config_for(points, rigs)
    config = config.model_copy(update={"sampler": Sampler(max_steps=1000, chunk_steps=500, seed=2)})
    folds = default_folds(list(dict.fromkeys(points["sweep_id"])), 2)
    job = FoldJob(points, rigs, config, "paper", 0, tuple((i, tuple(f)) for i, f in enumerate(folds)))
    with folds_in_background(job, workers=2) as collect:
        parallel = collect()
    here = run_folds(job)
    json.dump(
        {
            name: [fold.points["predicted_median"].tolist() + fold.points["observed_p97_5"].tolist() for fold in run]
            for name, run in (("parallel", parallel), ("here", here))
        },
        sys.stdout,
    )
    """
)


@pytest.mark.slow
def test_folds_run_in_workers_of_their_own_and_equal_the_folds_in_process(tmp_path):
    script, log = tmp_path / "no_guard.py", tmp_path / "runs.log"
    script.write_text(SCRIPT)
    done = subprocess.run([sys.executable, str(script), str(log)], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    assert log.read_text() == "ran\n"  # the workers did not run the script again
    result = json.loads(done.stdout)
    assert len(result["parallel"]) == 2 and all(len(fold) > 0 for fold in result["parallel"])
    assert result["parallel"] == result["here"]


@pytest.mark.slow
def test_a_folds_error_reaches_the_caller_as_one_line():
    points, rigs = simulate_campaign({"light_efficiency": 0.8}, seed=3, points_per_sweep=4)
    config = default_config_for(points, rigs)
    held_out, missing = list(dict.fromkeys(points["sweep_id"]))[:2]  # the training sweep's rig missing: no sampling
    job = FoldJob(points, {k: v for k, v in rigs.items() if k != missing}, config, None, 0, ((0, (held_out,)),))
    with pytest.raises(UwlabError, match="no rig recorded for this sweep"):
        with folds_in_background(job, workers=1) as collect:
            collect()
