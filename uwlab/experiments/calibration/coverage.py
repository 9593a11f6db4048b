"""Simulation-based check of credible-interval calibration (Cook, Gelman & Rubin 2006; Talts et al. 2018,
"Validating Bayesian inference algorithms with simulation-based calibration").

For each seed the true parameters are drawn from the fit's own priors, a campaign is simulated on the rig with
those truths, and the fit's central 95 % intervals are checked against them. When the model, the simulation and
the sampler agree, each interval contains its truth with probability 0.95. The model discrepancy is not counted:
the simulation has none, a truth on its prior's boundary.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Callable

import numpy as np

from uwlab.experiments.calibration.fit import FitConfig, Sampler, fit_points
from uwlab.experiments.calibration.priors import HalfNormal, LogNormal, Normal, Prior
from uwlab.experiments.calibration.simulate import simulate_campaign
from uwlab.model.optics import NO_LENS, LensSetting

COVERAGE_PRIORS = {
    "light_efficiency": LogNormal(median=0.8, sigma=0.2),
    "attenuation_scale": LogNormal(median=1.0, sigma=0.3),
    "K_dn_per_e:imx250m": Normal(mean=0.3473, sigma=0.0174, lo=0.0),
    "discrepancy": HalfNormal(sigma=0.05),
}
COVERAGE_LENSES = (LensSetting(30.0, 2.0), NO_LENS)


@dataclass
class Coverage:
    hits: int = 0
    total: int = 0
    misses: list[dict] = field(default_factory=list)

    @property
    def fraction(self) -> float:
        return self.hits / self.total


def interval_coverage(
    seeds: int,
    priors: dict[str, Prior] = COVERAGE_PRIORS,
    lenses=COVERAGE_LENSES,
    sensors=("imx250m",),
    points_per_sweep: int = 8,
    progress: Callable[[int], None] | None = None,
) -> Coverage:
    """Fraction of 95 % intervals containing the truth, over `seeds` simulated campaigns (truths ~ priors)."""
    result = Coverage()
    for seed in range(seeds):
        rng = np.random.default_rng(100 + seed)
        truth = {name: prior.sample(rng) for name, prior in priors.items() if name != "discrepancy"}
        points, rigs = simulate_campaign(
            truth, sensors=sensors, lenses=lenses, points_per_sweep=points_per_sweep, seed=seed
        )
        summary = fit_points(points, rigs, FitConfig(priors=priors, sampler=Sampler(seed=seed))).summary()
        for name, value in truth.items():
            p = summary["parameters"][name]
            inside = p["p2_5"] <= value <= p["p97_5"]
            result.hits += inside
            result.total += 1
            if not inside:
                result.misses.append(
                    {"seed": seed, "parameter": name, "truth": float(value), "p2_5": p["p2_5"], "p97_5": p["p97_5"]}
                )
        if progress:
            progress(seed)
    return result
