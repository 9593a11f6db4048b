"""The one conversion of uwlab results to JSON-able Python values (used by every `--json` and every JSON file).

Rules: dicts keep their keys (as strings), lists, tuples and numpy arrays become lists; numpy scalars and 0-d
arrays become Python numbers; a non-finite float (inf, nan) becomes ``None`` (JSON has no infinity: an unbounded
depth of field is "no limit", a missing value is null); paths become strings; dates and times ISO 8601 strings.
Anything else is a programming error (`TypeError`), never silently stringified.

>>> import numpy as np
>>> to_jsonable({"far_m": np.inf, "fov_deg": np.array([12.0, 10.5]), "ok": np.bool_(True)})
{'far_m': None, 'fov_deg': [12.0, 10.5], 'ok': True}
"""

from __future__ import annotations

import datetime as _dt
import json
import math
from pathlib import PurePath
from typing import Any

import numpy as np


def to_jsonable(value: Any) -> Any:
    """`value` as nested dicts/lists of str, int, float, bool and None (see the module docstring)."""
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.item()) if value.ndim == 0 else [to_jsonable(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if value is None or isinstance(value, (str, bool, int)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, PurePath):
        return str(value)
    if isinstance(value, (_dt.datetime, _dt.date, _dt.time)):
        return value.isoformat()
    raise TypeError(f"not JSON-able: {type(value).__name__}")


def dumps(value: Any, indent: int | None = None) -> str:
    """`json.dumps` of `to_jsonable(value)` (strict JSON: no NaN or Infinity tokens)."""
    return json.dumps(to_jsonable(value), indent=indent, allow_nan=False)
