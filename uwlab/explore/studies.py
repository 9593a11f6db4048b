"""The explorer's studies of a design, from request bodies: a sweep over one or two keys (what
`uwlab design --grid` evaluates) and the inverse design (`uwlab design solve`).

Both bodies carry the design as every request does (`uwlab.explore.inputs`: ``config``, ``set``, ``text``) and:

- sweep: ``grid``, {"section.key": "START:STOP:STEP" or "V1,V2,..." (the text of ``--grid``) or a list of values},
  one or two keys in order (the heatmap's rows, then its columns); ``output``, an output name as
  `uwlab design solve` names them (``snr_db``, ``dof_m.near``, ``light_budget_stops.aperture``).
- solve: ``free``, ["SECTION.KEY=LO:HI", ...]; ``require``, ["OUTPUT OP VALUE", ...]; ``objectives``,
  [{"minimize": "SECTION.KEY"} or {"maximize": "SECTION.KEY"}, one or two] — the arguments of ``--free``,
  ``--require``, ``--minimize`` / ``--maximize`` in order.
"""

from __future__ import annotations

import numpy as np

from uwlab.model.config import parse_grid_values
from uwlab.errors import ConfigError
from uwlab.experiments.design.grid import DesignGrid, flatten_outputs, in_memory_frame
from uwlab.experiments.design.readout import output_leaves
from uwlab.experiments.design.solve import Objective, Problem, parse_free, parse_requirement, result_dict, solve
from uwlab.explore import figures
from uwlab.explore.inputs import Served, check_file, design_raw
from uwlab.jsonable import to_jsonable
from uwlab.model.build import build_design
from uwlab.model.evaluation import evaluate

SWEEP_POINTS = 250_000  # a sweep the page draws; larger grids belong in `uwlab design --grid --out`


def _axes(grid) -> dict[str, list]:
    if not isinstance(grid, dict) or not 1 <= len(grid) <= 2:
        raise ConfigError("grid", grid, 'give one or two keys: {"section.key": "START:STOP:STEP" or "V1,V2,..."}')
    axes = {}
    for key, spec in grid.items():
        values = parse_grid_values(key, spec) if isinstance(spec, str) else spec
        if not isinstance(values, list) or not values:
            raise ConfigError(key, spec, "grid values must be START:STOP:STEP, V1,V2,... or a list")
        axes[key] = [float(v) if isinstance(v, np.floating) else v for v in values]
    return axes


def _column(name: str) -> str:
    """The grid column of an output name (``dof_m.near`` → its flattened column)."""
    parts = name.split(".")
    nested: dict = {parts[-1]: 0.0}
    for part in reversed(parts[:-1]):
        nested = {part: nested}
    return next(iter(flatten_outputs(nested)))


def sweep_answer(body, served: Served) -> dict:
    """{"axes", "output", "label", "unit", "values" (1-D, or 2-D with the first key's values as rows), "points",
    "figure"} of a sweep body."""
    raw = design_raw(body, served, extra=("grid", "output"))
    axes = _axes(body.get("grid"))
    for key, values in axes.items():
        for value in values:
            check_file(key, value, served)
    name = body.get("output")
    leaves = {leaf["name"]: leaf for leaf in output_leaves(to_jsonable(evaluate(build_design(raw, served.base_dir))))}
    if name not in leaves:
        raise ConfigError("output", name, f"unknown output; outputs are {', '.join(leaves)}")
    grid = DesignGrid(raw, axes, served.base_dir)
    if grid.points > SWEEP_POINTS:
        raise ConfigError(
            "grid",
            f"{grid.points} points",
            f"more than {SWEEP_POINTS} points; use uwlab design --grid ... --out FILE.parquet",
        )
    frame = in_memory_frame(grid)
    order = list(grid.categorical) + list(grid.numeric)  # the grid's row order (outermost first)
    values = frame[_column(name)].to_numpy(float).reshape([len(axes[k]) for k in order])
    values = values.transpose([order.index(k) for k in axes])
    leaf = leaves[name]
    return {
        "axes": axes,
        "output": name,
        "label": leaf["label"],
        "unit": leaf["unit"],
        "values": values,
        "points": grid.points,
        "figure": figures.sweep_figure(axes, values, name, leaf["label"], leaf["unit"]),
    }


def _objectives(items) -> list[Objective]:
    if not isinstance(items, list):
        raise ConfigError("objectives", items, 'must be a list of {"minimize": KEY} or {"maximize": KEY}')
    objectives = []
    for item in items:
        if not (isinstance(item, dict) and len(item) == 1 and next(iter(item)) in ("minimize", "maximize")):
            raise ConfigError("objectives", item, 'must be {"minimize": KEY} or {"maximize": KEY}')
        sense, key = next(iter(item.items()))
        objectives.append(Objective(key, sense))
    return objectives


def _texts(body: dict, member: str) -> list[str]:
    items = body.get(member, [])
    if not isinstance(items, list) or not all(isinstance(i, str) for i in items):
        raise ConfigError(member, items, "must be a list of strings")
    return items


def solve_answer(body, served: Served) -> dict:
    """{"answer": the object `uwlab design solve --json` prints, "figure": the Pareto front (two objectives)}."""
    raw = design_raw(body, served, extra=("free", "require", "objectives"))
    free = [parse_free(text) for text in _texts(body, "free")]
    requirements = [parse_requirement(text) for text in _texts(body, "require")]
    problem = Problem(raw, served.base_dir, free, requirements, _objectives(body.get("objectives", [])))
    answer = to_jsonable(result_dict(solve(problem), problem))
    figure = None
    if answer["feasible"] and "front" in answer:
        figure = front_figure(answer)
    return {"answer": answer, "figure": figure}


def front_figure(answer: dict) -> dict:
    """The Pareto front of two objectives: the second objective's key across, the first's up."""
    first, second = (o["key"] for o in answer["objectives"])
    points = answer["front"]
    x = [p["solution"][second] for p in points]
    y = [p["solution"][first] for p in points]
    text = ["; ".join(p["active"]) or "none" for p in points]
    trace = {
        "type": "scatter",
        "mode": "lines+markers",
        "x": x,
        "y": y,
        "text": text,
        "name": "Pareto front",
        "hovertemplate": f"{second} = %{{x:.4g}}<br>{first} = %{{y:.4g}}<br>active: %{{text}}<extra></extra>",
    }
    return {
        "data": [trace],
        "layout": figures.layout(
            "Pareto front", 360, xaxis=figures.axis(second, log=_wide(x)), yaxis=figures.axis(first, log=_wide(y))
        ),
    }


def _wide(values: list[float]) -> bool:
    """Positive values spanning more than a decade are drawn on a log axis."""
    return min(values) > 0 and max(values) / min(values) > 10
