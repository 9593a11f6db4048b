"""Evaluating a design over a Cartesian grid of parameters in one vectorised call per categorical combination.

Numeric parameters become an open mesh (one array axis each), so every model quantity is computed only over the
axes it depends on and broadcast at the end. Categorical parameters (water type, sensor profile, ...) are
evaluated one combination at a time. The result is one tidy table: a column per varied parameter and per output.
"""
from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pandas as pd

from uwlab.errors import ConfigError
from uwlab.model.config import apply_override
from uwlab.model.design import build_design, evaluate


def flatten_outputs(result: dict, prefix: str = "") -> dict[str, object]:
    """{"fov_deg": {"x": ..}} → {"fov_deg_x": ..}; None outputs are dropped."""
    flat = {}
    for key, value in result.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten_outputs(value, f"{name}_"))
        elif value is not None:
            flat[name] = value
    return flat


def _split(axes: dict[str, list]) -> tuple[dict[str, np.ndarray], dict[str, list]]:
    numeric, categorical = {}, {}
    for key, values in axes.items():
        if not values:
            raise ConfigError(key, values, "grid has no values")
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
            numeric[key] = np.asarray(values, float)
        else:
            categorical[key] = list(values)
    return numeric, categorical


def evaluate_grid(raw: dict, axes: dict[str, list], base_dir: Path | None = None) -> pd.DataFrame:
    """Evaluate the design `raw` (a config dict) at every point of the Cartesian product of `axes`."""
    numeric, categorical = _split(axes)
    names = list(numeric)
    mesh = {k: v.reshape([-1 if i == j else 1 for j in range(len(names))]) for i, (k, v) in enumerate(numeric.items())}
    frames = []
    for combo in itertools.product(*categorical.values()):
        config = {s: dict(b) if isinstance(b, dict) else b for s, b in raw.items()}
        for key, value in zip(categorical, combo):
            apply_override(config, key, value)
        for key, value in mesh.items():
            apply_override(config, key, value)
        result = flatten_outputs(evaluate(build_design(config, base_dir)))
        shape = tuple(len(v) for v in numeric.values())
        columns = {k: np.broadcast_to(v, shape).ravel() for k, v in mesh.items()}
        columns.update({k: np.broadcast_to(np.asarray(v), shape).ravel() for k, v in result.items()})
        frame = pd.DataFrame(columns)
        for key, value in zip(categorical, combo):
            frame.insert(0, key, value)
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)
