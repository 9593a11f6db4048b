"""A whole campaign's calibration at lab scale: 24 configurations (2 cameras × 6 focal lengths × 2 apertures) of
30 exposures each, simulated on the fly (never committed), fitted with its held-out folds and checks as `uwlab fit`
does (`uwlab.experiments.calibration.pipeline.assess`: the full fit, two held-out fold fits, posterior predictive
checks). Issue 26's target: minutes, not hours, on two cores. Prints one JSON object: the time of each stage,
points, configurations, convergence, peak memory.

Usage: python benchmarks/bench_fit_campaign.py
"""

from __future__ import annotations

import json
import resource
import time

from uwlab.experiments.calibration.fit import default_config_for, fit_points
from uwlab.experiments.calibration.pipeline import assess
from uwlab.experiments.calibration.simulate import simulate_campaign
from uwlab.experiments.calibration.validation import default_folds
from uwlab.model.optics import LensSetting

TRUTH = {"light_efficiency": 0.8, "attenuation_scale": 1.1, "K_dn_per_e:imx250m": 0.35, "K_dn_per_e:icx285alm": 1.1}
LENSES = tuple(LensSetting(f, n) for f in (8.0, 12.0, 16.0, 25.0, 30.0, 50.0) for n in (2.0, 4.0))


def main() -> dict:
    t0 = time.perf_counter()
    points, rigs = simulate_campaign(TRUTH, lenses=LENSES, points_per_sweep=30, max_fraction=0.9, seed=11)
    simulated = time.perf_counter() - t0
    usable = points[~points["saturated"]]
    config = default_config_for(usable, rigs)
    t1 = time.perf_counter()
    alone = fit_points(points, rigs, config)
    fit_s = time.perf_counter() - t1
    sweeps = list(dict.fromkeys(usable["sweep_id"]))
    t2 = time.perf_counter()
    assessment = assess(points, rigs, config, default_folds(sweeps, config.holdout.folds))
    assess_s = time.perf_counter() - t2
    return {
        "configurations": len(sweeps),
        "points": int(len(usable)),
        "free_parameters": len(alone.names),
        "simulate_s": round(simulated, 1),
        "fit_s": round(fit_s, 1),
        "fit_converged": bool(alone.converged),
        "fit_steps": int(alone.steps),
        "fit_walkers": int(alone.chain.shape[1]),
        "assess_s (fit + held-out folds + checks)": round(assess_s, 1),
        "held_out_inside_95": assessment.cross.inside_95,
        "held_out_band_sharpness": assessment.cross.sharpness,
        "folds_converged": [fold["converged"] for fold in assessment.cross.folds],
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "target": "minutes, not hours, on two cores",
    }


if __name__ == "__main__":
    print(json.dumps(main(), indent=2))
