"""Cost of one vectorised log-posterior call of a fit (`Posterior.log_u`, what emcee calls ≈ 2.4 times a step with
half the walkers each time), and a digest of its values to compare before/after a change that must keep them.

The data are `bench_fit`'s simulated campaign (2 cameras × 3 lens settings, saturated points excluded) with its
priors and the between-configuration scale; 18 walker positions around the prior medians in the sampling
coordinates, a fixed seed. Prints one JSON object: median and minimum seconds per call over repeated batches, and
the SHA-256 of the log densities at 200 such position sets (the same digest means bit-identical values).
"""

from __future__ import annotations

import hashlib
import json
import time

import numpy as np

from uwlab.experiments.calibration.fit import Posterior
from uwlab.experiments.calibration.forward import build_forward_model
from uwlab.experiments.calibration.priors import HalfNormal
from uwlab.experiments.calibration.simulate import simulate_campaign

from bench_fit import PRIORS, TRUTH

WALKERS = 18
CALLS = 500
BATCHES = 7


def main() -> None:
    points, rigs = simulate_campaign(TRUTH, points_per_sweep=40, max_fraction=0.9, seed=7)
    used = points[~points["saturated"].astype(bool)]
    priors = {**PRIORS, "config_discrepancy": HalfNormal(sigma=0.02)}
    model = build_forward_model(used, rigs, tuple(priors))
    post = Posterior(model, priors)
    start = np.array([max(priors[n].quantile(0.5), 1e-3) for n in model.names])
    u0 = post.to_u(start)
    rng = np.random.default_rng(0)
    digest = hashlib.sha256()
    for scale in np.geomspace(1e-3, 3.0, 200):  # from the mode's neighbourhood to far outside the priors (−inf)
        digest.update(post.log_u(u0 + scale * rng.standard_normal((WALKERS, u0.size))).tobytes())
    u = u0 + 0.01 * rng.standard_normal((WALKERS, u0.size))
    for _ in range(CALLS // 2):  # warm-up
        post.log_u(u)
    per_call = []
    for _ in range(BATCHES):
        t0 = time.perf_counter()
        for _ in range(CALLS):
            post.log_u(u)
        per_call.append((time.perf_counter() - t0) / CALLS)
    print(
        json.dumps(
            {
                "free_parameters": len(model.names),
                "points": int(model.y.size),
                "walkers": WALKERS,
                "median_s_per_call": float(np.median(per_call)),
                "min_s_per_call": float(np.min(per_call)),
                "log_u_sha256": digest.hexdigest(),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
