"""uwlab: design, calibration and validation of underwater camera systems.

The Python API mirrors the command line verb for verb (docs/api.md pairs each README workflow with its Python
equivalent):

- design: `load_design`, `evaluate` (→ `Evaluation`), `design_figures` (→ matplotlib Figures), `grid`
  (→ DataFrame; ``.to_xarray()``), `solve` (→ DataFrame, the Pareto front);
- campaigns: `load_plan`, `sweep` (→ `Dataset`), `Dataset.open` (``.points``, ``.spectra``);
- camera characterisation: `characterize` (→ `EmvaResult`; ``.figures()``), `characterize_on_bench` (the
  simulated EMVA 1288 bench);
- calibration: `fit` (→ `Fit`: ``.posterior`` an ``arviz.InferenceData``, ``.verdict``, ``.predict(design)``,
  ``.figures()``), `report`;
- instruments: `open_camera`, `open_light`, `open_spectrometer`, `grab`;
- `config_path`: a file of the bundled configs (designs, plans, rigs, sensors).

``import uwlab`` loads none of them: each name is imported on first use (PEP 562), so the import stays fast.

>>> import uwlab
>>> design = uwlab.load_design(uwlab.config_path("design/example.toml"), operation__exposure_s="max-blur")
>>> result = uwlab.evaluate(design)
>>> f"{result['snr_db']:.1f} {result.units['snr_db']}"
'36.5 dB'
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

# Public name -> the module defining it (imported on first use).
_EXPORTS: dict[str, str] = {
    "load_design": "uwlab.api.design",
    "evaluate": "uwlab.api.design",
    "design_figures": "uwlab.api.design",
    "Evaluation": "uwlab.api.design",
    "grid": "uwlab.api.design",
    "solve": "uwlab.api.design",
    "Infeasible": "uwlab.api.design",
    "load_plan": "uwlab.api.campaign",
    "sweep": "uwlab.api.campaign",
    "Dataset": "uwlab.api.campaign",
    "characterize": "uwlab.api.emva",
    "characterize_on_bench": "uwlab.api.emva",
    "EmvaResult": "uwlab.api.emva",
    "fit": "uwlab.api.calibration",
    "Fit": "uwlab.api.calibration",
    "Verdict": "uwlab.api.calibration",
    "report": "uwlab.api.calibration",
    "open_camera": "uwlab.api.instruments",
    "open_light": "uwlab.api.instruments",
    "open_spectrometer": "uwlab.api.instruments",
    "grab": "uwlab.api.instruments",
    "Grab": "uwlab.api.instruments",
    "config_path": "uwlab.api.paths",
}

__all__ = ["__version__", *_EXPORTS]

# The names' types are declared in __init__.pyi (type checkers read it; importing them here, even under
# TYPE_CHECKING, would make every module that reads `__version__` depend on the whole API for import-linter).


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'uwlab' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
