"""Is a calibrated model adequate? Named checks on a calibration, the verdict, and the likely causes of a failure.

The model is adequate when every check passes:

- ``convergence``: the fit and every held-out fold's fit reached 50 autocorrelation times.
- ``held-out levels``: each held-out configuration's level (the median of measured / predicted − 1) is consistent
  with the prediction for a new configuration, two-sided p ≥ 0.01 / n over the n held-out configurations (a 1 %
  false-alarm rate for the whole check, Bonferroni).
- ``held-out coverage``: at least `MIN_HELD_OUT_INSIDE` of the held-out points lie inside their 95 % bands. The
  points of one configuration share its discrepancy, so the fraction scatters widely about 95 % even for a good
  model; the bound catches bands that are plainly too narrow.
- ``within-configuration fit``: the χ² posterior predictive p of every fitted configuration ≥ 0.01 / n.
- ``within-configuration trend``: no configuration's residuals drift with its swept variable
  (`uwlab.experiments.calibration.validation.residual_trend`) by `MAX_TREND_PERCENT` or more over the sweep with
  a slope p < 0.01 / n: a drift needs both, significance and a size that matters for a design. A drift against
  exposure, light level or gain is named what it usually is: an unmodelled response non-linearity, or the light
  drifting while the sweep ran (its points are taken in order of the swept variable).
- ``between-configuration discrepancy``: the median of τ at most `MAX_CONFIG_DISCREPANCY` (beyond it a new
  configuration is predicted no better than ±2τ).
- ``point discrepancy``: the median within-configuration discrepancy at most `MAX_POINT_DISCREPANCY`.

Likely causes, for the paper chain: the effects it leaves out, evaluated with the extended chain
(`uwlab.model.extended`) on the same rigs at the posterior median attenuation scale (`neglected_effects`):
veiling light reaching `BACKSCATTER_NAMED` of a configuration's signal names ``backscatter``; the lights'
placement, beam profile and the board's size changing the ratio of the two chains across configurations by
`GEOMETRY_NAMED` or more names ``light and board geometry``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from uwlab.errors import ConfigError
from uwlab.experiments.calibration.fit import FitResult
from uwlab.experiments.calibration.forward import extended_roi_rates
from uwlab.experiments.calibration.validation import CrossValidation

FAMILY_ALPHA = 0.01
MIN_HELD_OUT_INSIDE = 0.75
MAX_CONFIG_DISCREPANCY = 0.10
MAX_POINT_DISCREPANCY = 0.05
MAX_TREND_PERCENT = 0.5  # end-to-end residual change over one sweep [%]
SIGNAL_VARIABLES = ("exposure_us", "light_level", "gain_db")  # sweeps along which the signal itself grows
SWEPT_LABELS = {
    "exposure_us": ("exposure", "µs"),
    "f_number": ("f-number", ""),
    "gain_db": ("gain", "dB"),
    "light_level": ("light level", ""),
}
BACKSCATTER_NAMED = 0.02
GEOMETRY_NAMED = 0.05


@dataclass(frozen=True)
class Check:
    """One named check: passed or not, and what it found, in words."""

    name: str
    passed: bool
    detail: str


def checks(result: FitResult, ppc: pd.DataFrame, cross: CrossValidation) -> list[Check]:
    """The named checks of the module docstring."""
    out = []
    unconverged = [f"fold {i + 1}" for i, f in enumerate(cross.folds) if not f["converged"]]
    if not result.converged:
        unconverged.insert(0, "the full fit")
    out.append(
        Check(
            "convergence",
            not unconverged,
            "every fit reached 50 autocorrelation times"
            if not unconverged
            else f"not converged: {', '.join(unconverged)}",
        )
    )
    table = cross.table
    if len(table):
        bound = FAMILY_ALPHA / len(table)
        off = table[table["level_p"] < bound]
        out.append(
            Check(
                "held-out levels",
                off.empty,
                f"every held-out configuration within its prediction (p ≥ {bound:.2g})"
                if off.empty
                else "held-out configuration(s) off their prediction: "
                + ", ".join(
                    f"{r.sweep_id} by {r.level_offset_percent:+.1f} % (p = {r.level_p:.2g})" for r in off.itertuples()
                ),
            )
        )
        inside = cross.inside_95
        out.append(
            Check(
                "held-out coverage",
                inside >= MIN_HELD_OUT_INSIDE,
                f"{100 * inside:.0f} % of the held-out points inside their 95 % bands",
            )
        )
    if len(ppc):
        bound = FAMILY_ALPHA / len(ppc)
        off = ppc[ppc["ppc_p"] < bound]
        out.append(
            Check(
                "within-configuration fit",
                off.empty,
                "every configuration's points scatter as the model allows"
                if off.empty
                else "points scatter about the model more than it allows in "
                + ", ".join(f"{r.sweep_id} (p = {r.ppc_p:.2g})" for r in off.itertuples()),
            )
        )
    if len(ppc) and "trend_p" in ppc:
        out.append(trend_check(ppc))
    tau = result.median("config_discrepancy")
    if tau is not None:
        out.append(
            Check(
                "between-configuration discrepancy",
                tau <= MAX_CONFIG_DISCREPANCY,
                f"configurations differ from the model by {100 * tau:.1f} % (typical, median of τ)",
            )
        )
    delta = result.median("discrepancy")
    if delta is not None:
        out.append(
            Check(
                "point discrepancy",
                delta <= MAX_POINT_DISCREPANCY,
                f"points within a configuration differ from the model by {100 * delta:.1f} %",
            )
        )
    return out


def trend_check(ppc: pd.DataFrame) -> Check:
    """``within-configuration trend`` (module docstring) from the ``trend_*`` columns of the posterior predictive
    checks."""
    trends = ppc[ppc["trend_p"].notna()]
    if trends.empty:
        return Check("within-configuration trend", True, "no sweep has 4 or more values of its variable")
    bound = FAMILY_ALPHA / len(trends)
    change = trends["trend_end_percent"] - trends["trend_start_percent"]
    off = trends[(trends["trend_p"] < bound) & (change.abs() >= MAX_TREND_PERCENT)]
    if off.empty:
        worst = trends.loc[change.abs().idxmax()]
        return Check(
            "within-configuration trend",
            True,
            f"no residual drift of {MAX_TREND_PERCENT:g} % or more along any sweep (largest "
            f"{worst.trend_start_percent:+.2f} → {worst.trend_end_percent:+.2f} % in {worst.sweep_id})",
        )
    worst = off.loc[(off["trend_end_percent"] - off["trend_start_percent"]).abs().idxmax()]
    name, unit = SWEPT_LABELS.get(worst.trend_variable, (worst.trend_variable, ""))
    what = (
        "unmodelled response non-linearity (or the light drifting during the sweep)"
        if worst.trend_variable in SIGNAL_VARIABLES
        else "residual trend"
    )
    return Check(
        "within-configuration trend",
        False,
        f"{what}: the residuals drift with {name} in {len(off)} of {len(trends)} configurations, most in "
        f"{worst.sweep_id} ({worst.trend_start_percent:+.1f} → {worst.trend_end_percent:+.1f} % over "
        f"{worst.trend_low:.3g}–{worst.trend_high:.3g}{' ' + unit if unit else ''}, p = {worst.trend_p:.2g})",
    )


def neglected_effects(result: FitResult) -> pd.DataFrame:
    """Per configuration of a paper-chain fit: the veiling light's share of the signal [%] and the ratio of the
    extended chain's target signal to the paper chain's, both at the posterior median attenuation scale. Empty
    when the rigs cannot be evaluated by the extended chain (lights not placed: the paper's light at the camera)."""
    model = result.model
    scale = result.median("attenuation_scale") or model.nominal["attenuation_scale"]
    rows = []
    for k, design in enumerate(model.designs):
        sel = model.config == k
        roi = (float(model.points.loc[sel, "roi_w"].median()), float(model.points.loc[sel, "roi_h"].median()))
        extended = design.with_values(**{"model.kind": "extended", "water.attenuation_scale": scale})
        try:
            direct, veil = (float(x) for x in extended_roi_rates(extended, bool(model.has_lens[k]), *roi))
        except ConfigError:
            return pd.DataFrame(columns=["sweep_id", "veil_percent", "extended_over_paper"])
        paper = model.nominal_rate_e_per_s[k] * float(model.transmission(np.array([scale]))[0, k])
        rows.append(
            {
                "sweep_id": str(model.points.loc[np.flatnonzero(sel)[0], "sweep_id"]),
                "veil_percent": 100 * veil / (direct + veil),
                "extended_over_paper": direct / paper,
            }
        )
    return pd.DataFrame(rows)


def likely_causes(neglected: pd.DataFrame) -> list[str]:
    """Plain-language causes from `neglected_effects` (module docstring), the largest first."""
    causes: list[tuple[float, str]] = []
    if len(neglected) == 0:
        return []
    worst = neglected.loc[neglected["veil_percent"].idxmax()]
    if worst["veil_percent"] >= 100 * BACKSCATTER_NAMED:
        causes.append(
            (
                worst["veil_percent"] / 100,
                f"backscatter: veiling light scattered by the water is {worst['veil_percent']:.1f} % of the "
                f"signal in {worst['sweep_id']} ({neglected['veil_percent'].min():.1f} % at least); the paper "
                "model leaves it out — fit with the extended model (--model extended)",
            )
        )
    ratio = neglected["extended_over_paper"]
    spread = float(ratio.max() / ratio.min() - 1)
    if spread >= GEOMETRY_NAMED:
        low = neglected.loc[ratio.idxmin(), "sweep_id"]
        causes.append(
            (
                spread,
                f"light and board geometry: the lights' placement, beam profile and the board's size "
                f"change the response by {100 * spread:.0f} % between configurations (least in {low}); "
                "the paper model assumes a uniform beam and a board filling the view",
            )
        )
    return [text for _, text in sorted(causes, key=lambda c: -c[0])]


@dataclass(frozen=True)
class Verdict:
    adequate: bool
    checks: list[Check]
    causes: list[str]

    def warnings(self) -> list[str]:
        """The failing checks, then the likely causes."""
        failing = [f"model inadequate — {c.name}: {c.detail}" for c in self.checks if not c.passed]
        return failing + (["likely cause — " + cause for cause in self.causes] if failing else [])

    def to_dict(self) -> dict:
        return {
            "model_adequate": self.adequate,
            "checks": [asdict(c) for c in self.checks],
            "likely_causes": self.causes,
        }


def verdict(result: FitResult, ppc: pd.DataFrame, cross: CrossValidation) -> Verdict:
    """The checks, the verdict and, for a paper-chain fit, the likely causes."""
    found = checks(result, ppc, cross)
    causes = likely_causes(neglected_effects(result)) if result.model.kind == "paper" else []
    return Verdict(all(c.passed for c in found), found, causes)
