"""The trend check's rule: a drift fails only when it is both significant (slope p < 0.01 / n) and large enough to
matter (≥ 0.5 % over the sweep); its line names the worst configuration with the swept variable's unit."""

from __future__ import annotations

import numpy as np
import pandas as pd

from uwlab.experiments.calibration.adequacy import trend_check
from uwlab.experiments.calibration.validation import residual_trend


def ppc(*trends):
    return pd.DataFrame(
        [
            {
                "sweep_id": f"s{i}",
                "trend_variable": variable,
                "trend_low": 20.0,
                "trend_high": 460.0,
                "trend_start_percent": start,
                "trend_end_percent": end,
                "trend_p": p,
            }
            for i, (variable, start, end, p) in enumerate(trends)
        ]
    )


def test_significant_and_large_fails_with_the_worst_named():
    check = trend_check(ppc(("exposure_us", 0.3, -0.3, 1e-3), ("exposure_us", 0.6, -0.6, 1e-7)))
    assert not check.passed
    assert check.detail == (
        "unmodelled response non-linearity (or the light drifting during the sweep): the residuals drift with "
        "exposure in 2 of 2 configurations, most in s1 (+0.6 → -0.6 % over 20–460 µs, p = 1e-07)"
    )


def test_small_or_insignificant_drifts_pass():
    assert trend_check(ppc(("exposure_us", 0.2, -0.2, 1e-9))).passed  # significant but 0.4 % over the sweep
    assert trend_check(ppc(("exposure_us", 2.0, -2.0, 0.01))).passed  # large but p ≥ 0.01 / 1
    # Bonferroni: p = 0.004 fails alone, passes among 3 configurations
    assert not trend_check(ppc(("f_number", 0.5, -0.5, 0.004))).passed
    assert trend_check(ppc(*[("f_number", 0.5, -0.5, 0.004)] * 3)).passed


def test_an_aperture_drift_is_a_residual_trend_not_a_non_linearity():
    check = trend_check(ppc(("f_number", 1.0, -1.0, 1e-6)))
    assert check.detail.startswith("residual trend: the residuals drift with f-number")


def test_the_slope_test_is_calibrated_on_pure_noise():
    # residuals without any trend: p is uniform, so about 1 % of sweeps fall below 0.01
    rng = np.random.default_rng(0)
    rows = pd.DataFrame({"exposure_us": np.geomspace(20, 500, 12)})
    p = np.array([residual_trend("exposure", rows, rng.normal(0, 0.2, 12)).p for _ in range(2000)])
    assert 0.005 < np.mean(p < 0.01) < 0.02
    assert residual_trend("dark", rows, np.zeros(12)) is None
    assert residual_trend("exposure", rows.iloc[:3], np.zeros(3)) is None
