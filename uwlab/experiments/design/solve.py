"""Inverse design: the values of some free keys that meet every requirement, with the least (or most) of one or
two of them.

Problem: free keys x_k ∈ [LO_k, HI_k]; requirements "OUTPUT >= VALUE" or "OUTPUT <= VALUE" on the outputs of
`uwlab.model.evaluation.evaluate` (nested keys with a dot: ``dof_m.near``); objectives: one or two free keys to
minimise or maximise. The other free keys are nuisance: any value in their range may be chosen. With a posterior
(`uwlab.experiments.design.posterior`), the requirements must all hold together with probability ≥ the
confidence, estimated over the posterior samples.

Method (the model is vectorised, so grids are cheap; no black-box optimiser). Free keys are mapped to a unit
coordinate, logarithmic when LO > 0. With two objectives the second one is swept over `FRONT_POINTS` values, one
"slot" each (one slot otherwise).
1. Bracket: feasibility on a grid of the first objective × the nuisance keys, per slot.
2. Refine: for every slot and nuisance point, the first objective between its last infeasible and first feasible
   grid value is bisected (`BISECTION_STEPS`, all at once in one vectorised evaluation per step). Feasibility is
   assumed to change once inside a grid cell: outputs are monotone in lumens, f-number, exposure... over a cell.
3. Nuisance keys: the best nuisance point of each slot, then a box of ±2 cells around it, `ZOOM_ROUNDS` times.
4. Front (two objectives): the ends of the feasible range of the second objective are bisected too; points
   dominated by another are dropped (Pareto filter).
5. Checks at each solution: minimality (1 % less of a minimised objective, or 1 % more of a maximised one,
   is infeasible for every nuisance value of a fine grid), the active requirements (those a 1 % change of one
   free key breaks), the keys sitting at a bound.
When nothing is feasible, each requirement is tried alone over the whole box: those that fail even at their best
are named with the best value reached; if each can be met alone, the pairs that cannot be met together.
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError
from uwlab.experiments.design.posterior import DesignPosterior
from uwlab.jsonable import to_jsonable
from uwlab.model.config import apply_override
from uwlab.model.build import build_design
from uwlab.model.design import Design
from uwlab.model.evaluation import evaluate

OPERATORS = (">=", "<=")
FRONT_POINTS = 33
BISECTION_STEPS = 48
ZOOM_ROUNDS = 6
STEP = 0.01  # the 1 % of minimality and of the active test
EVALUATIONS_PER_CALL = 400_000  # candidates × posterior samples per vectorised evaluation


@dataclass(frozen=True)
class FreeKey:
    """A free config key and its range; `unit` maps it to [0, 1] (logarithmically when lo > 0)."""

    key: str
    lo: float
    hi: float

    @property
    def log(self) -> bool:
        return self.lo > 0

    def value(self, t):
        t = np.asarray(t, float)
        return self.lo * (self.hi / self.lo) ** t if self.log else self.lo + t * (self.hi - self.lo)

    def unit(self, x):
        x = np.asarray(x, float)
        return np.log(x / self.lo) / np.log(self.hi / self.lo) if self.log else (x - self.lo) / (self.hi - self.lo)


@dataclass(frozen=True)
class Requirement:
    """OUTPUT OP VALUE on an output of `evaluate` (``dof_m.near`` for nested keys)."""

    output: str
    op: str
    value: float

    def __str__(self) -> str:
        return f"{self.output} {self.op} {self.value:g}"

    def of(self, outputs: dict) -> np.ndarray:
        return output_value(outputs, self.output)

    def met(self, outputs: dict) -> np.ndarray:
        x = self.of(outputs)
        return x >= self.value if self.op == ">=" else x <= self.value


@dataclass(frozen=True)
class Objective:
    key: str
    sense: str  # "minimize" or "maximize"


def output_value(outputs: dict, name: str):
    """outputs["a"]["b"] for "a.b"; a missing or absent (None) output is a ConfigError naming it."""
    value = outputs
    for part in name.split("."):
        if not isinstance(value, dict) or part not in value:
            raise ConfigError("--require", name, "unknown output; see the keys of `uwlab design --json`")
        value = value[part]
    if value is None:
        raise ConfigError("--require", name, "this design does not compute that output")
    if isinstance(value, dict):
        raise ConfigError("--require", name, f"choose one of {', '.join(f'{name}.{k}' for k in value)}")
    value = np.asarray(value)
    if value.dtype == bool:
        raise ConfigError("--require", name, "a flag, not a number")
    return value


def parse_free(text: str) -> FreeKey:
    key, eq, bounds = text.partition("=")
    lo, colon, hi = bounds.partition(":")
    try:
        lo_v, hi_v = float(lo), float(hi)
    except ValueError:
        raise ConfigError("--free", text, "expected SECTION.KEY=LO:HI with numbers") from None
    if not eq or not colon or not key.strip() or not (math.isfinite(lo_v) and math.isfinite(hi_v)) or not lo_v < hi_v:
        raise ConfigError("--free", text, "expected SECTION.KEY=LO:HI with LO < HI")
    return FreeKey(key.strip(), lo_v, hi_v)


_REQUIREMENT = re.compile(r"^\s*([A-Za-z_][\w.]*)\s*(>=|<=)\s*(\S+)\s*$")


def parse_requirement(text: str) -> Requirement:
    match = _REQUIREMENT.match(text)
    if not match:
        raise ConfigError("--require", text, 'expected "OUTPUT >= VALUE" or "OUTPUT <= VALUE"')
    try:
        value = float(match.group(3))
    except ValueError:
        raise ConfigError("--require", text, "VALUE must be a number") from None
    if not math.isfinite(value):
        raise ConfigError("--require", text, "VALUE must be finite")
    return Requirement(match.group(1), match.group(2), value)


class Problem:
    """A design, its free keys, requirements and objectives; evaluates feasibility of candidate values."""

    def __init__(
        self,
        raw: dict,
        base_dir: Path | None,
        free: list[FreeKey],
        requirements: list[Requirement],
        objectives: list[Objective],
        posterior_loader=None,
        confidence: float = 1.0,
    ):
        keys = [f.key for f in free]
        if len(set(keys)) != len(keys):
            raise ConfigError("--free", ", ".join(keys), "a key is given twice")
        if not requirements:
            raise ConfigError("--require", None, "give at least one requirement")
        if not 1 <= len(objectives) <= 2:
            raise ConfigError("--minimize", None, "give one or two objectives (--minimize / --maximize)")
        for objective in objectives:
            if objective.key not in keys:
                raise ConfigError(f"--{objective.sense}", objective.key, "must be one of the --free keys")
        if len({o.key for o in objectives}) != len(objectives):
            raise ConfigError(f"--{objectives[-1].sense}", objectives[-1].key, "an objective is given twice")
        if not 0 < confidence <= 1:
            raise ConfigError("--confidence", confidence, "must be in (0, 1]")
        for f in free:  # every bound is a valid design (names the key and value otherwise)
            for bound in (f.lo, f.hi):
                config = {s: dict(b) if isinstance(b, dict) else b for s, b in raw.items()}
                apply_override(config, f.key, bound)
                build_design(config, base_dir)
        self.design: Design = build_design(raw, base_dir)
        order = [o.key for o in objectives] + [k for k in keys if k not in {o.key for o in objectives}]
        self.free = [next(f for f in free if f.key == k) for k in order]
        self.requirements = requirements
        self.objectives = objectives
        self.confidence = confidence
        self.posterior: DesignPosterior | None = posterior_loader(self.design) if posterior_loader else None
        probe = evaluate(self.design)
        for requirement in requirements:
            requirement.of(probe)

    @property
    def samples(self) -> int:
        return 1 if self.posterior is None else self.posterior.size

    def values(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """Unit coordinates (n, k) → {key: values (n,)}."""
        return {f.key: f.value(t[:, i]) for i, f in enumerate(self.free)}

    def outputs(self, values: dict[str, np.ndarray]) -> dict:
        design = self.design.with_values(**values)
        return evaluate(design if self.posterior is None else self.posterior.apply(design))

    def probabilities(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(joint probability that every requirement holds (n,), each requirement's own probability (n, m)) at
        unit coordinates t (n, k); 0 or 1 without a posterior. Evaluated in slices of bounded size."""
        n = t.shape[0]
        joint = np.empty(n)
        each = np.empty((n, len(self.requirements)))
        step = max(1, EVALUATIONS_PER_CALL // self.samples)
        for s in range(0, n, step):
            out = self.outputs(self.values(t[s : s + step]))
            shape = (min(step, n - s),) + ((self.samples,) if self.posterior is not None else ())
            met = np.stack([np.broadcast_to(r.met(out), shape) for r in self.requirements], axis=-1)
            axis = 1 if self.posterior is not None else None
            joint[s : s + step] = met.all(axis=-1).mean(axis=axis) if axis else met.all(axis=-1)
            each[s : s + step] = met.mean(axis=axis) if axis else met
        return joint, each

    def feasible(self, t: np.ndarray) -> np.ndarray:
        return self.probabilities(t)[0] >= self.confidence * (1 - 1e-12)


@dataclass
class Solution:
    """One solution (or one point of a Pareto front)."""

    values: dict[str, float]
    outputs: dict
    probability: float
    active: list[str]
    at_bounds: list[str]
    minimal: bool
    pareto: bool | None = None


@dataclass
class SolveResult:
    feasible: bool
    solutions: list[Solution] = field(default_factory=list)
    unmet: list[dict] = field(default_factory=list)
    conflicting: list[list[str]] = field(default_factory=list)


def _cost_to_unit(objective: Objective, c):
    return np.asarray(c) if objective.sense == "minimize" else 1 - np.asarray(c)


def _unit_grid(n: int, dims: int) -> np.ndarray:
    """All points of an n-per-axis grid on [0, 1]^dims, shape (n^dims, dims)."""
    if dims == 0:
        return np.zeros((1, 0))
    axes = np.linspace(0.0, 1.0, n)
    return np.array(list(itertools.product(axes, repeat=dims)))


class Solver:
    """The steps of the module docstring for one `Problem`."""

    def __init__(self, problem: Problem):
        self.p = problem
        self.k_nuisance = len(problem.free) - len(problem.objectives)
        budget = EVALUATIONS_PER_CALL * 4 // problem.samples
        two = len(problem.objectives) == 2
        self.n_primary = 65 if (two or self.k_nuisance) else 1025
        slots = FRONT_POINTS if two else 1
        if self.k_nuisance:
            n = int((max(budget // (slots * self.n_primary), 9)) ** (1 / self.k_nuisance))
            self.n_nuisance = max(3, n - (1 - n % 2))  # odd: the zoom keeps the best point on the grid
        else:
            self.n_nuisance = 1

    def _assemble(self, primary_c, secondary_t, nuisance_t) -> np.ndarray:
        """Unit coordinates (n, k) from costs of the first objective, units of the second (or None), nuisance."""
        cols = [_cost_to_unit(self.p.objectives[0], primary_c)]
        if secondary_t is not None:
            cols.append(secondary_t)
        t = np.column_stack(cols + ([nuisance_t] if nuisance_t is not None and nuisance_t.size else []))
        return t

    def optimise(self, secondary_t: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """For each slot (second-objective unit value, or one slot): the least cost c* of the first objective
        over the nuisance keys (inf when infeasible) and the nuisance units there."""
        slots = 1 if secondary_t is None else secondary_t.size
        k = self.k_nuisance
        lo, hi = np.zeros((slots, k)), np.ones((slots, k))
        best_c = np.full(slots, np.inf)
        best_u = np.full((slots, k), 0.5)
        offsets = _unit_grid(self.n_nuisance, k) if k else np.zeros((1, 0))
        costs = np.linspace(0.0, 1.0, self.n_primary)
        for _ in range(ZOOM_ROUNDS if k else 1):
            u = lo[:, None, :] + (hi - lo)[:, None, :] * offsets[None, :, :]  # (slots, U, k)
            n_u = offsets.shape[0]
            c_star = self._refine(secondary_t, u.reshape(slots * n_u, k), n_u, costs)
            c_star = c_star.reshape(slots, n_u)
            pick = np.argmin(c_star, axis=1)
            round_c = c_star[np.arange(slots), pick]
            round_u = u[np.arange(slots), pick]
            better = round_c < best_c
            best_c = np.where(better, round_c, best_c)
            best_u = np.where(better[:, None], round_u, best_u)
            cell = (hi - lo) / max(self.n_nuisance - 1, 1)
            lo = np.clip(best_u - 2 * cell, 0.0, 1.0)
            hi = np.clip(best_u + 2 * cell, 0.0, 1.0)
        return best_c, best_u

    def _refine(self, secondary_t, u: np.ndarray, n_u: int, costs: np.ndarray) -> np.ndarray:
        """Grid over the first objective's cost for every (slot, nuisance point), then bisection of the first
        infeasible → feasible cell; inf where no cost is feasible."""
        rows = u.shape[0]
        slot_t = None if secondary_t is None else np.repeat(secondary_t, n_u)
        c_grid = np.tile(costs, rows)
        feasible = self.p.feasible(
            self._assemble(
                c_grid, None if slot_t is None else np.repeat(slot_t, costs.size), np.repeat(u, costs.size, axis=0)
            )
        ).reshape(rows, costs.size)
        any_feasible = feasible.any(axis=1)
        first = np.argmax(feasible, axis=1)
        result = np.where(any_feasible, costs[first], np.inf)
        todo = any_feasible & (first > 0)
        if todo.any():
            lo_c, hi_c = costs[first[todo] - 1], costs[first[todo]]
            for _ in range(BISECTION_STEPS):
                mid = 0.5 * (lo_c + hi_c)
                ok = self.p.feasible(self._assemble(mid, None if slot_t is None else slot_t[todo], u[todo]))
                hi_c = np.where(ok, mid, hi_c)
                lo_c = np.where(ok, lo_c, mid)
            result[todo] = hi_c
        return result

    def any_feasible_at(self, secondary_t: np.ndarray) -> np.ndarray:
        """Whether some first-objective and nuisance grid value is feasible, per second-objective unit value."""
        grid = _unit_grid(self.n_nuisance, self.k_nuisance)
        costs = np.linspace(0.0, 1.0, self.n_primary)
        rows = secondary_t.size
        c = np.tile(np.repeat(costs, grid.shape[0]), rows)
        u = np.tile(grid, (rows * costs.size, 1))
        s = np.repeat(secondary_t, costs.size * grid.shape[0])
        ok = self.p.feasible(self._assemble(c, s, u))
        return np.asarray(np.asarray(ok).reshape(rows, -1).any(axis=1))

    def bisect_secondary(self, inside: float, outside: float) -> float:
        """The boundary of the feasible range of the second objective between a feasible and an infeasible
        unit value."""
        for _ in range(BISECTION_STEPS // 2):
            mid = 0.5 * (inside + outside)
            if self.any_feasible_at(np.array([mid]))[0]:
                inside = mid
            else:
                outside = mid
        return inside


def solve(problem: Problem) -> SolveResult:
    """Run the method of the module docstring."""
    solver = Solver(problem)
    if len(problem.objectives) == 1:
        c, u = solver.optimise(None)
        if not np.isfinite(c[0]):
            return _diagnose(problem)
        t = solver._assemble(c, None, u)[0]
        return SolveResult(True, [_describe(problem, solver, t)])
    secondary = np.linspace(0.0, 1.0, FRONT_POINTS)
    c, u = solver.optimise(secondary)
    ok = np.isfinite(c)
    if not ok.any():
        return _diagnose(problem)
    extra = []
    for i in range(FRONT_POINTS - 1):  # ends of feasible ranges: bisect between neighbours
        if ok[i] != ok[i + 1]:
            inside, outside = (secondary[i], secondary[i + 1]) if ok[i] else (secondary[i + 1], secondary[i])
            extra.append(solver.bisect_secondary(inside, outside))
    if extra:
        c_extra, u_extra = solver.optimise(np.array(extra))
        secondary = np.concatenate([secondary, extra])
        c, u = np.concatenate([c, c_extra]), np.concatenate([u, u_extra])
        ok = np.isfinite(c)
    t = solver._assemble(c[ok], secondary[ok], u[ok])
    points = [_describe(problem, solver, row) for row in _pareto(problem, t)]
    return SolveResult(True, points)


def _pareto(problem: Problem, t: np.ndarray) -> np.ndarray:
    """Rows of t not dominated by another row (both objectives as costs), ordered by the second objective."""
    cost = np.column_stack([_cost_to_unit(o, t[:, i]) for i, o in enumerate(problem.objectives)])
    order = np.lexsort((cost[:, 0], cost[:, 1]))
    keep, best = [], np.inf
    for i in order:
        if cost[i, 0] < best - 1e-12:
            keep.append(i)
            best = cost[i, 0]
    return t[sorted(keep, key=lambda i: t[i, 1])]


def _describe(problem: Problem, solver: Solver, t: np.ndarray) -> Solution:
    values = {f.key: float(f.value(t[i])) for i, f in enumerate(problem.free)}
    joint, _ = problem.probabilities(t[None, :])
    at_bounds = [f.key for i, f in enumerate(problem.free) if t[i] <= 1e-12 or t[i] >= 1 - 1e-12]
    active = _active(problem, t)
    minimal = _improvement_infeasible(problem, solver, t, 0)
    pareto = _improvement_infeasible(problem, solver, t, 1) if len(problem.objectives) == 2 else None
    outputs = evaluate(problem.design.with_values(**values))
    return Solution(values, outputs, float(joint[0]), active, at_bounds, minimal, pareto)


def _moved(problem: Problem, t: np.ndarray, index: int, factor: float) -> np.ndarray | None:
    """t with free key `index` multiplied by `factor`, or None outside its range."""
    free = problem.free[index]
    x = float(free.value(t[index])) * factor
    if not free.lo <= x <= free.hi:
        return None
    moved = t.copy()
    moved[index] = free.unit(x)
    return moved


def _active(problem: Problem, t: np.ndarray) -> list[str]:
    """Requirements that a 1 % change (either way) of one free key breaks (below the confidence)."""
    moved = [
        m for i in range(len(problem.free)) for f in (1 - STEP, 1 + STEP) if (m := _moved(problem, t, i, f)) is not None
    ]
    if not moved:
        return []
    _, each = problem.probabilities(np.array(moved))
    broken = np.asarray(np.asarray(each < problem.confidence * (1 - 1e-12)).any(axis=0))
    return [str(r) for r, b in zip(problem.requirements, broken, strict=True) if b]


def _improvement_infeasible(problem: Problem, solver: Solver, t: np.ndarray, index: int) -> bool:
    """Whether objective `index` made 1 % better (others fixed, nuisance keys anywhere on a fine grid) fails."""
    objective = problem.objectives[index]
    moved = _moved(problem, t, index, 1 - STEP if objective.sense == "minimize" else 1 + STEP)
    if moved is None:
        return True
    k = solver.k_nuisance
    n = max(3, int((EVALUATIONS_PER_CALL // problem.samples) ** (1 / k))) if k else 1
    grid = _unit_grid(min(n, 65), k)
    candidates = np.repeat(moved[None, :], grid.shape[0] + 1, axis=0)
    if k:
        candidates[1:, len(problem.objectives) :] = grid
    return not problem.feasible(candidates).any()


def _diagnose(problem: Problem) -> SolveResult:
    """Which requirements cannot be met even at the bounds (alone), else which pairs cannot be met together."""
    k = len(problem.free)
    n = max(3, int((EVALUATIONS_PER_CALL * 4 // problem.samples) ** (1 / k)))
    t = _unit_grid(min(n, 1025), k)
    _, each = problem.probabilities(t)
    alone = each >= problem.confidence * (1 - 1e-12)
    unmet = []
    nominal = problem.outputs if problem.posterior is None else None
    for j, requirement in enumerate(problem.requirements):
        if alone[:, j].any():
            continue
        if nominal is not None:
            values = np.broadcast_to(requirement.of(problem.outputs(problem.values(t))), (t.shape[0],))
            best = int(np.argmax(values) if requirement.op == ">=" else np.argmin(values))
            entry = {"requirement": str(requirement), "best": float(values[best])}
        else:
            best = int(np.argmax(each[:, j]))
            entry = {"requirement": str(requirement), "best_probability": float(each[best, j])}
        entry["at"] = {key: float(v[0]) for key, v in problem.values(t[best : best + 1]).items()}
        unmet.append(entry)
    conflicting = []
    if not unmet:
        for a, b in itertools.combinations(range(len(problem.requirements)), 2):
            together = (alone[:, a] & alone[:, b]) if problem.posterior is None else None
            if together is not None and not together.any():
                conflicting.append([str(problem.requirements[a]), str(problem.requirements[b])])
        if problem.posterior is not None or not conflicting:
            conflicting.append([str(r) for r in problem.requirements])
    return SolveResult(False, [], unmet, conflicting)


def solution_dict(solution: Solution, problem: Problem) -> dict:
    """One solution as JSON-able data: the free keys' values, the design's outputs (the keys of `uwlab design
    --json`), the active requirements, the checks and, with a posterior, the probability reached."""
    entry = {
        "solution": solution.values,
        "outputs": to_jsonable(solution.outputs),
        "active": solution.active,
        "minimal": solution.minimal,
        "at_bounds": solution.at_bounds,
    }
    if solution.pareto is not None:
        entry["pareto"] = solution.pareto
    if problem.posterior is not None:
        entry["probability"] = solution.probability
    return entry


def result_dict(result: SolveResult, problem: Problem) -> dict:
    """The answer of `uwlab design solve --json` (see docs/design.md)."""
    head = {
        "feasible": result.feasible,
        "objectives": [{"key": o.key, "sense": o.sense} for o in problem.objectives],
        "requirements": [str(r) for r in problem.requirements],
    }
    if problem.posterior is not None:
        head["confidence"] = problem.confidence
        head["posterior"] = {
            "fit": str(problem.posterior.fit_dir),
            "samples": problem.posterior.size,
            "carried": list(problem.posterior.carried),
        }
    if not result.feasible:
        return {**head, "unmet": result.unmet, "conflicting": result.conflicting}
    if len(problem.objectives) == 1:
        return {**head, **solution_dict(result.solutions[0], problem)}
    return {**head, "front": [solution_dict(s, problem) for s in result.solutions]}


def front_frame(result: SolveResult, problem: Problem):
    """The Pareto front as a table: free keys, flattened outputs, checks (and probability with a posterior)."""
    import pandas as pd

    from uwlab.experiments.design.grid import flatten_outputs

    rows = []
    for s in result.solutions:
        row: dict[str, object] = dict(s.values)
        row.update({k: np.asarray(v).item() for k, v in flatten_outputs(s.outputs).items()})
        row.update(active="; ".join(s.active), minimal=s.minimal, pareto=s.pareto)
        if problem.posterior is not None:
            row["probability"] = s.probability
        rows.append(row)
    return pd.DataFrame(rows)
