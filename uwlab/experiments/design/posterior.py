"""The calibration's uncertainty carried into a design: posterior samples of a `uwlab fit` output applied to the
design's chain.

A fit (`uwlab.experiments.calibration`) describes the tank set-up; what transfers to another design are its
correction factors, applied per posterior sample θ_s:

- light efficiency ε (true / rated flux): the luminous flux is multiplied by ε;
- attenuation scale s: the design's attenuation scale is multiplied by s (the correction of the water model
  learned in the tank, whose nominal scale is 1);
- system gain K of a calibrated camera: when the design's sensor profile is one of the fit's cameras
  (``K_dn_per_e:<profile>``), K is multiplied by K_s / K_profile, i.e. the gain by 20 log₁₀(K_s / K_profile) dB;
- fractional model discrepancy δ: the prediction of a new measurement is μ (1 + δ z), z ~ N(0, 1), applied to the
  flux with one seeded z per sample. A design is a configuration the fit has not seen, so δ combines the fit's
  discrepancy within a configuration δ_w and, when the fit has one, the scale τ of its discrepancies between
  configurations (`uwlab.experiments.calibration.fit`): δ = √(δ_w² + τ²).

Parameters the fit did not sample keep their design values. Other fitted parameters (beam angle, reflectance,
lens transmittance) describe the tank's own light, board and lenses and are not carried over.

Known gap (issue 35's lens groups): a fit with `lens_transmittance:<setting>` and `bare_sensor_factor` learns the
lens groups' ratios, and its τ is only what remains once they are fitted (seed-0 demo: median 0.09 %, 97.5th
percentile 0.87 %, against ≈ 1.4 % when τ also carried the lenses). A design's own lens is not among the fit's,
and the uncertainty of its transmittance against its table (the 5 % the fit's lens priors state) is not added
here, so the band of a design with a new lens is too narrow by about that much.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from uwlab.errors import ConfigError
from uwlab.model.design import Design
from uwlab.model.evaluation import evaluate

MAX_SAMPLES = 1000
PERCENTILES = {"p2_5": 2.5, "p16": 16.0, "median": 50.0, "p84": 84.0, "p97_5": 97.5}
BAND_OUTPUTS = ("mean_electrons", "mean_dn", "mean_fraction", "snr", "snr_db")


@dataclass(frozen=True)
class DesignPosterior:
    """Per-sample factors (arrays of one length S) for a design; see the module docstring."""

    fit_dir: Path
    light_efficiency: np.ndarray
    attenuation_scale: np.ndarray
    k_factor: np.ndarray
    discrepancy: np.ndarray
    z: np.ndarray
    calibrated_camera: str | None
    carried: tuple[str, ...]

    @property
    def size(self) -> int:
        return self.light_efficiency.size

    def apply(self, design: Design) -> Design:
        """The design with a trailing sample axis: the design's arrays (all with the same number of axes) get a
        length-1 axis, the calibrated factors vary along the new one."""
        arrays = _arrays(design)
        ndim = max((v.ndim for v in arrays.values()), default=0)
        if any(v.ndim != ndim for v in arrays.values()):
            raise ValueError("the design's arrays must share their number of axes")
        lifted = {key: value[..., None] for key, value in arrays.items()}
        base = lambda key: lifted.get(key, design[key])  # noqa: E731
        along = lambda values: values.reshape((1,) * ndim + (-1,))  # noqa: E731
        multiplier = self.light_efficiency * np.maximum(1 + self.discrepancy * self.z, 0.0)
        return design.with_values(
            **{
                **lifted,
                "light.luminous_flux_lm": base("light.luminous_flux_lm") * along(multiplier),
                "water.attenuation_scale": base("water.attenuation_scale") * along(self.attenuation_scale),
                "sensor.gain_db": base("sensor.gain_db") + along(20 * np.log10(self.k_factor)),
            }
        )


def _arrays(design: Design) -> dict[str, np.ndarray]:
    return {
        f"{s}.{k}": v
        for s, body in design.values.items()
        if isinstance(body, dict)
        for k, v in body.items()
        if isinstance(v, np.ndarray)
    }


def load_posterior(
    fit_dir: str | Path, design: Design, max_samples: int = MAX_SAMPLES, seed: int = 0
) -> DesignPosterior:
    """The posterior of the fit in `fit_dir` (its ``samples.parquet``) as factors for `design`; at most
    `max_samples` samples, evenly thinned from the chain order."""
    fit_dir = Path(fit_dir)
    path = fit_dir / "samples.parquet"
    if not path.is_file():
        raise ConfigError("--posterior", str(fit_dir), "no samples.parquet here (not a `uwlab fit` output directory)")
    try:
        samples = pd.read_parquet(path)
    except (OSError, ValueError) as exc:
        raise ConfigError("--posterior", str(path), f"unreadable ({exc})") from None
    if len(samples) == 0:
        raise ConfigError("--posterior", str(path), "holds no samples")
    keep = np.unique(np.linspace(0, len(samples) - 1, min(max_samples, len(samples))).round().astype(int))
    samples = samples.iloc[keep].reset_index(drop=True)
    n = len(samples)

    def column(name, default):
        return samples[name].to_numpy(float) if name in samples else np.full(n, default)

    profile = str(design["sensor.profile"])
    k_column = f"K_dn_per_e:{Path(profile).stem.lower()}"
    calibrated = k_column in samples
    k_factor = samples[k_column].to_numpy(float) / design.sensor.K_dn_per_e if calibrated else np.ones(n)
    carried = tuple(
        name
        for name in ("light_efficiency", "attenuation_scale", "discrepancy", "config_discrepancy")
        if name in samples
    )
    carried += (k_column,) if calibrated else ()
    posterior = DesignPosterior(
        fit_dir=fit_dir,
        light_efficiency=column("light_efficiency", 1.0),
        attenuation_scale=column("attenuation_scale", 1.0),
        k_factor=k_factor,
        discrepancy=np.hypot(column("discrepancy", 0.0), column("config_discrepancy", 0.0)),
        z=np.random.default_rng(seed).standard_normal(n),
        calibrated_camera=profile if calibrated else None,
        carried=carried,
    )
    for name, values, lo in (
        ("light_efficiency", posterior.light_efficiency, 0.0),
        ("attenuation_scale", posterior.attenuation_scale, -1e-300),
        (k_column, posterior.k_factor, 0.0),
        ("discrepancy", posterior.discrepancy, -1e-300),
    ):
        if not np.all(np.isfinite(values)) or np.any(values <= lo):
            raise ConfigError("--posterior", str(path), f"{name} samples must be finite and positive")
    return posterior


def credible_band(design: Design, posterior: DesignPosterior) -> dict:
    """Percentiles (2.5, 16, 50, 84, 97.5) over the posterior of the response and SNR of a single design, and
    the share of samples that saturate."""
    out = evaluate(posterior.apply(design))
    band = {}
    columns = {key: out[key] for key in BAND_OUTPUTS} | {"image_average_mean_dn": out["image_average"]["mean_dn"]}
    for key, value in columns.items():
        q = np.percentile(np.broadcast_to(value, (posterior.size,)), list(PERCENTILES.values()))
        band[key] = dict(zip(PERCENTILES, q.tolist(), strict=True))
    return {
        "fit": str(posterior.fit_dir),
        "samples": posterior.size,
        "carried": list(posterior.carried),
        "saturated_fraction": float(np.mean(np.broadcast_to(out["saturated"], (posterior.size,)))),
        **band,
    }
