"""Prior distributions for model calibration, with vectorised log densities.

A prior is declared in a fit config as a table, e.g. ``{ kind = "lognormal", median = 1.0, sigma = 0.5 }``:
- ``normal``: mean, sigma;  ``lognormal``: median, sigma (of the natural log);  ``uniform``: lo, hi;
  ``halfnormal``: sigma (support x ≥ 0).
Optional ``lo``/``hi`` truncate any prior (log density −inf outside; the normalisation constant of a truncated
prior is omitted, which does not change the posterior).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uwlab.errors import ConfigError

_PARAMS = {"normal": ("mean", "sigma"), "lognormal": ("median", "sigma"), "uniform": ("lo", "hi"), "halfnormal": ("sigma",)}


@dataclass(frozen=True)
class Prior:
    kind: str
    a: float = 0.0
    b: float = 1.0
    lo: float = -np.inf
    hi: float = np.inf

    def logpdf(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.kind == "normal":
                out = -0.5 * ((x - self.a) / self.b) ** 2
            elif self.kind == "lognormal":
                safe = np.where(x > 0, x, 1.0)
                out = np.where(x > 0, -0.5 * (np.log(safe / self.a) / self.b) ** 2 - np.log(safe), -np.inf)
            elif self.kind == "uniform":
                out = np.where((x >= self.a) & (x <= self.b), 0.0, -np.inf)
            else:
                out = np.where(x >= 0, -0.5 * (x / self.a) ** 2, -np.inf)
        return np.where((x >= self.lo) & (x <= self.hi), out, -np.inf)

    def sample(self, rng: np.random.Generator, size=None) -> np.ndarray:
        """Draws from the (truncated) prior by rejection."""
        n = 1 if size is None else int(np.prod(size))
        out = np.empty(0)
        while out.size < n:
            if self.kind == "normal":
                draw = rng.normal(self.a, self.b, 4 * n)
            elif self.kind == "lognormal":
                draw = self.a * np.exp(rng.normal(0.0, self.b, 4 * n))
            elif self.kind == "uniform":
                draw = rng.uniform(self.a, self.b, 4 * n)
            else:
                draw = np.abs(rng.normal(0.0, self.a, 4 * n))
            out = np.concatenate([out, draw[(draw >= self.lo) & (draw <= self.hi)]])
        return out[0] if size is None else out[:n].reshape(size)

    def median(self) -> float:
        if self.kind == "normal":
            return float(np.clip(self.a, self.lo, self.hi))
        if self.kind == "lognormal":
            return float(np.clip(self.a, self.lo, self.hi))
        if self.kind == "uniform":
            return 0.5 * (self.a + self.b)
        return float(np.clip(0.6745 * self.a, self.lo, self.hi))


def parse_prior(key: str, spec) -> Prior:
    """A prior from its config table; ConfigError names the key."""
    if not isinstance(spec, dict) or "kind" not in spec:
        raise ConfigError(key, spec, 'must be a table with kind = "normal"|"lognormal"|"uniform"|"halfnormal"')
    kind = spec["kind"]
    if kind not in _PARAMS:
        raise ConfigError(f"{key}.kind", kind, f"must be one of {', '.join(_PARAMS)}")
    allowed = set(_PARAMS[kind]) | {"kind", "lo", "hi"}
    for name, value in spec.items():
        if name not in allowed:
            raise ConfigError(f"{key}.{name}", value, f"unknown for a {kind} prior; expected {', '.join(sorted(allowed))}")
        if name != "kind" and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise ConfigError(f"{key}.{name}", value, "must be a number")
    names = _PARAMS[kind]
    for name in names:
        if name not in spec:
            raise ConfigError(f"{key}.{name}", None, f"missing for a {kind} prior")
    values = [float(spec[n]) for n in names]
    if kind in ("normal", "lognormal", "halfnormal") and values[-1] <= 0:
        raise ConfigError(f"{key}.sigma", values[-1], "must be > 0")
    if kind == "lognormal" and values[0] <= 0:
        raise ConfigError(f"{key}.median", values[0], "must be > 0")
    if kind == "uniform" and values[1] <= values[0]:
        raise ConfigError(f"{key}.hi", values[1], "must exceed lo")
    lo, hi = float(spec.get("lo", -np.inf)), float(spec.get("hi", np.inf))
    if kind == "uniform":
        lo, hi = max(lo, values[0]), min(hi, values[1])
    if not lo < hi:
        raise ConfigError(f"{key}.hi", hi, "must exceed lo")
    return Prior(kind, *(values + [1.0] * (2 - len(values))), lo=lo, hi=hi)
