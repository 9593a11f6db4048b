"""False-alarm and detection rates of the within-configuration trend check over simulated campaigns.

For each seed, the paper's tank rig (4 configurations: IMX250 and ICX285 × 30 mm F2, 12 mm F4; 12-point exposure
sweeps) is rendered by a tank world with only the sensor's response non-linearity switched on
(tests/support/worlds.py), fitted with the linear chain, and checked. Non-linearity 0 measures false alarms (the
check's family-wise rate is designed at ≤ 1 %, and a drift must also reach 0.5 %); 1 % and 3 % at full well
measure detection. The χ² posterior predictive check's rate on the same campaigns is printed beside it.

Usage: python benchmarks/bench_trend_check.py [SEEDS]   (default 20; prints JSON)
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.support.worlds import nonlinear_sensor_rig
from uwlab.experiments.calibration.adequacy import FAMILY_ALPHA, trend_check
from uwlab.experiments.calibration.fit import fit_points
from uwlab.experiments.calibration.simulate import simulate_campaign
from uwlab.experiments.calibration.validation import posterior_predictive_checks

TRUTH = {"light_efficiency": 0.8, "attenuation_scale": 1.2, "K_dn_per_e:imx250m": 0.36, "K_dn_per_e:icx285alm": 1.05}


def main(seeds: int) -> dict:
    started = time.perf_counter()
    result: dict = {"seeds": seeds, "configurations_per_campaign": None, "worlds": {}}
    with tempfile.TemporaryDirectory() as folder:
        for nonlinearity in (0.0, 0.01, 0.03):
            rig = nonlinear_sensor_rig(Path(folder), nonlinearity)
            fired, chi2_fired, largest = 0, 0, []
            for seed in range(seeds):
                points, rigs = simulate_campaign(TRUTH, seed=seed, rig=rig, world=None)
                ppc = posterior_predictive_checks(fit_points(points, rigs))
                result["configurations_per_campaign"] = len(ppc)
                fired += not trend_check(ppc).passed
                chi2_fired += bool((ppc["ppc_p"] < FAMILY_ALPHA / len(ppc)).any())
                largest.append(float((ppc["trend_end_percent"] - ppc["trend_start_percent"]).abs().max()))
            result["worlds"][f"nonlinearity_{nonlinearity:g}"] = {
                "trend_check_fired": fired,
                "trend_check_rate": fired / seeds,
                "chi2_check_fired": chi2_fired,
                "largest_drift_percent_median": sorted(largest)[len(largest) // 2],
                "largest_drift_percent_max": max(largest),
            }
    result["seconds"] = round(time.perf_counter() - started, 1)
    return result


if __name__ == "__main__":
    print(json.dumps(main(int(sys.argv[1]) if len(sys.argv) > 1 else 20), indent=2))
