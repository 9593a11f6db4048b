# Types of the public names that uwlab/__init__.py loads on first use (PEP 562); keep in step with its _EXPORTS.
from typing import Any

from uwlab.api.calibration import Fit as Fit
from uwlab.api.calibration import Verdict as Verdict
from uwlab.api.calibration import fit as fit
from uwlab.api.calibration import report as report
from uwlab.api.campaign import Dataset as Dataset
from uwlab.api.campaign import load_plan as load_plan
from uwlab.api.campaign import sweep as sweep
from uwlab.api.design import Evaluation as Evaluation
from uwlab.api.design import Infeasible as Infeasible
from uwlab.api.design import design_figures as design_figures
from uwlab.api.design import evaluate as evaluate
from uwlab.api.design import grid as grid
from uwlab.api.design import load_design as load_design
from uwlab.api.design import solve as solve
from uwlab.api.emva import EmvaResult as EmvaResult
from uwlab.api.emva import characterize as characterize
from uwlab.api.emva import characterize_on_bench as characterize_on_bench
from uwlab.api.instruments import Grab as Grab
from uwlab.api.instruments import grab as grab
from uwlab.api.instruments import open_camera as open_camera
from uwlab.api.instruments import open_light as open_light
from uwlab.api.instruments import open_spectrometer as open_spectrometer
from uwlab.api.paths import config_path as config_path

__version__: str
__all__: list[str]

def __getattr__(name: str) -> Any: ...
def __dir__() -> list[str]: ...
