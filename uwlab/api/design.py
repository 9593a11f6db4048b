"""Designs from Python: `load_design`, `evaluate`, `design_figures`, `grid`, `solve` — `uwlab design` (``--plot``)
and `uwlab design solve`.

>>> import uwlab
>>> design = uwlab.load_design(uwlab.config_path("design/example.toml"), operation__exposure_s="max-blur")
>>> result = uwlab.evaluate(design)
>>> round(result["snr_db"], 1), result.units["snr_db"]
(36.5, 'dB')
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from uwlab.errors import ConfigError, UwlabError
from uwlab.model.design import Design

if TYPE_CHECKING:
    import pandas as pd

    from uwlab.api.calibration import Fit
    from uwlab.experiments.design.readout import DesignWarning
    from uwlab.experiments.figures import Figure


class Infeasible(UwlabError):
    """`solve` found no values of the free keys meeting every requirement; the message names the requirements that
    cannot be met (alone, even at the bounds, or together); `answer` is the solver's full answer (the JSON of
    ``uwlab design solve --json``).

    >>> import uwlab
    >>> try:
    ...     uwlab.solve(uwlab.load_design(uwlab.config_path("design/example.toml")),
    ...                 free={"light.luminous_flux_lm": (100, 1000)}, require=["snr_db >= 60"],
    ...                 minimize="light.luminous_flux_lm")
    ... except uwlab.Infeasible as exc:
    ...     print(exc)
    no feasible design: cannot be met even at the bounds: snr_db >= 60
    """

    def __init__(self, message: str, answer: dict[str, Any]) -> None:
        super().__init__(message)
        self.answer = answer


def _dotted(key: str) -> str:
    """``lens__f_number`` (a Python keyword) or ``lens.f_number`` → ``lens.f_number``."""
    return key if "." in key else key.replace("__", ".", 1)


def load_design(path: str | Path, **overrides: Any) -> Design:
    """Read a design TOML (`configs/design/example.toml` documents every key), apply overrides, validate.

    Parameters
    ----------
    path
        The design file (a bundled one by name: ``"design/example.toml"``; `uwlab.api.paths.config_file`).
    **overrides
        Values replacing the file's: ``section__key=value`` (``lens__f_number=4.0``) or, with a dotted key,
        ``**{"lens.f_number": 4.0}`` — the keys of ``uwlab design --set``.

    Returns
    -------
    Design
        The validated design (`uwlab.model.design.Design`). Bad input raises `uwlab.errors.ConfigError` naming the
        key and value.

    Examples
    --------
    >>> import uwlab
    >>> design = uwlab.load_design(uwlab.config_path("design/example.toml"), operation__altitude_m=2.0)
    >>> design["operation.altitude_m"], design.sensor.name
    (2.0, 'IMX250M')
    """
    from uwlab.api.paths import config_file
    from uwlab.model.build import load_design as load

    return load(config_file(path, "design"), {_dotted(k): v for k, v in overrides.items()})


@dataclass(frozen=True)
class Evaluation:
    """One design evaluated: every output with its unit, the warnings on them and the light budget.

    `outputs` holds the values as `uwlab design --json` prints them (nested tables such as ``dof_m`` as dicts,
    infinities as None); ``evaluation["dof_m.near"]`` reads one by its dotted name (the names
    `solve`'s requirements take); `units` and `labels` give each dotted name's unit and label; `light_budget` the
    stops of light lost per stage, `limiting_stage` the stage that loses most. ``str(evaluation)`` is the text
    table of ``uwlab design``.

    >>> import uwlab
    >>> result = uwlab.evaluate(uwlab.load_design(uwlab.config_path("design/example.toml")))
    >>> result["dof_m.near"] == result.outputs["dof_m"]["near"], result.units["dof_m.near"]
    (True, 'm')
    >>> print(str(result).splitlines()[0])
    effective focal length           39.99 mm
    """

    design: Design
    outputs: dict[str, Any]
    warnings: tuple[DesignWarning, ...]

    def __getitem__(self, name: str) -> Any:
        value: Any = self.outputs
        for part in name.split("."):
            if not isinstance(value, dict) or part not in value:
                raise KeyError(name)
            value = value[part]
        return value

    @property
    def units(self) -> dict[str, str]:
        """{dotted output name: unit} ("" for a pure number)."""
        from uwlab.experiments.design.readout import output_leaves

        return {leaf["name"]: leaf["unit"] for leaf in output_leaves(self.outputs)}

    @property
    def labels(self) -> dict[str, str]:
        """{dotted output name: label as the text table shows it}."""
        from uwlab.experiments.design.readout import output_leaves

        return {leaf["name"]: leaf["label"] for leaf in output_leaves(self.outputs)}

    @property
    def light_budget(self) -> dict[str, float | None]:
        """Stops of light lost per stage of the chain, lights → electrons (`uwlab.model.budget.light_budget`)."""
        from uwlab.experiments.design.readout import BUDGET_KEY

        return dict(self.outputs.get(BUDGET_KEY) or {})

    @property
    def limiting_stage(self) -> str:
        """The stage of `light_budget` that loses the most light."""
        from uwlab.experiments.design.readout import budget_rows

        return budget_rows(self.light_budget)[1]

    def to_pandas(self) -> pd.DataFrame:
        """One row per output (index: dotted name) with columns ``value``, ``unit``, ``label`` and ``warning``
        (the warnings on that output, "" when none)."""
        import pandas as pd

        notes: dict[str, list[str]] = {}
        for warning in self.warnings:
            for output in warning.outputs:
                notes.setdefault(output, []).append(warning.message)
        labels = self.labels
        rows = [
            {
                "name": name,
                "value": self[name],
                "unit": unit,
                "label": labels[name],
                "warning": "; ".join(notes.get(name, notes.get(name.split(".")[0], []))),
            }
            for name, unit in self.units.items()
        ]
        return pd.DataFrame(rows).set_index("name")

    def __str__(self) -> str:
        from uwlab.experiments.design.readout import table_text

        return table_text(self.outputs, list(self.warnings))

    def _repr_pretty_(self, printer: Any, cycle: bool) -> None:  # IPython's display
        printer.text(str(self))


def _has_arrays(design: Design) -> bool:
    """Whether any input of `design` holds several values (a grid, not one design)."""
    return any(
        isinstance(v, np.ndarray) and v.size != 1
        for body in design.values.values()
        if isinstance(body, dict)
        for v in body.values()
    )


def evaluate(design: Design) -> Evaluation:
    """Evaluate one design: FOV, exposure and framerate limits, depth of field, response, SNR, light budget.

    Examples
    --------
    >>> import uwlab
    >>> design = uwlab.load_design(uwlab.config_path("design/example.toml"), operation__exposure_s="max-blur")
    >>> result = uwlab.evaluate(design)
    >>> round(result["mean_dn"], 1), result.units["mean_dn"], result.limiting_stage
    (1537.3, 'DN', 'aperture')
    >>> table = result.to_pandas()
    >>> round(table.loc["fov_deg.x", "value"], 2), table.loc["fov_deg.x", "unit"]
    (12.06, 'deg')
    >>> [w.kind for w in result.warnings]
    ['dof']
    """
    from uwlab.experiments.design.readout import design_warnings
    from uwlab.jsonable import to_jsonable
    from uwlab.model.evaluation import evaluate as run

    if _has_arrays(design):
        raise ConfigError("design", "arrays", "evaluate takes one design; use uwlab.grid for many")
    outputs = to_jsonable(run(design))
    return Evaluation(design, outputs, tuple(design_warnings(design, outputs)))


def design_figures(design: Design) -> dict[str, Figure]:
    """The design figures of one design as matplotlib Figures (a notebook shows each inline), by name — the
    figures ``uwlab design --plot DIR`` writes as ``DIR/NAME.png``:

    - ``dof``: near and far depth-of-field limits against the f-number, for several focus distances;
    - ``spectra``: the spectrum at each stage of the on-axis chain;
    - ``operation``: the minimum framerate and maximum exposure against speed, for several altitudes;
    - ``water``: the beam attenuation of every water type;
    - ``qe``: the sensor's quantum efficiency.

    Examples
    --------
    >>> import uwlab
    >>> figures = uwlab.design_figures(uwlab.load_design(uwlab.config_path("design/example.toml")))
    >>> list(figures)
    ['dof', 'spectra', 'operation', 'water', 'qe']
    >>> [ax.get_xlabel() for ax in figures["operation"].axes]
    ['speed [m/s]', 'speed [m/s]']
    >>> figures["dof"].savefig("dof.png", dpi=110)  # doctest: +SKIP
    """
    from uwlab.experiments.design.plots import design_figures as draw

    if _has_arrays(design):
        raise ConfigError("design", "arrays", "design_figures takes one design; use uwlab.grid for many")
    return draw(design)


def _raw(design: Design) -> dict[str, Any]:
    from uwlab.experiments.acquisition.plan import resolved_rig

    return resolved_rig(design)


def _axis_values(key: str, values: Iterable[Any]) -> list[Any]:
    listed = np.asarray(values).tolist() if isinstance(values, np.ndarray) else list(values)
    if not listed:
        raise ConfigError(key, listed, "grid has no values")
    return listed


def grid(design: Design, axes: Mapping[str, Iterable[Any]], outputs: Sequence[str] | None = None) -> pd.DataFrame:
    """Evaluate the Cartesian grid of `axes` around `design`, in memory (``uwlab design --grid``).

    Parameters
    ----------
    design
        The base design (`load_design`).
    axes
        {dotted key: values} (``{"lens.f_number": [2, 4, 8], "water.type": ["jerlov-I", "jerlov-3C"]}``);
        numeric values may be a numpy array.
    outputs
        The flattened output columns to keep (``snr_db``, ``dof_m_near``, ...; default all).

    Returns
    -------
    pandas.DataFrame
        One row per grid point, indexed by the axes (a MultiIndex, in the order given), so that
        ``frame.to_xarray()`` is the gridded `xarray.Dataset` with one dimension per axis. A grid too large for
        memory is refused before anything is evaluated (stream it with ``uwlab design --grid ... --out``).

    Examples
    --------
    >>> import numpy as np, uwlab
    >>> design = uwlab.load_design(uwlab.config_path("design/example.toml"))
    >>> frame = uwlab.grid(design, {"operation.altitude_m": np.linspace(0.5, 2, 4), "lens.f_number": [2, 4]},
    ...                    outputs=["snr_db"])
    >>> frame.shape, list(frame.index.names)
    ((8, 1), ['operation.altitude_m', 'lens.f_number'])
    >>> frame.to_xarray()["snr_db"].dims
    ('operation.altitude_m', 'lens.f_number')
    """
    from uwlab.experiments.design.grid import DesignGrid, in_memory_frame

    listed = {_dotted(k): _axis_values(k, v) for k, v in axes.items()}
    frame = in_memory_frame(
        DesignGrid(_raw(design), listed, design.base_dir, outputs=tuple(outputs) if outputs is not None else None)
    )
    return frame.set_index(list(listed)) if listed else frame


def _posterior_dir(posterior: Fit | str | Path) -> Path:
    from uwlab.api.calibration import Fit

    return posterior.directory if isinstance(posterior, Fit) else Path(posterior)


def solve(
    design: Design,
    free: Mapping[str, tuple[float, float]],
    require: Sequence[str],
    minimize: str | Sequence[str] = (),
    maximize: str | Sequence[str] = (),
    posterior: Fit | str | Path | None = None,
    confidence: float | None = None,
) -> pd.DataFrame:
    """Inverse design (``uwlab design solve``): values of the `free` keys meeting every requirement with the least
    (`minimize`) and/or most (`maximize`) of one or two of them.

    Parameters
    ----------
    design
        The base design.
    free
        {dotted key: (lo, hi)} the solver may choose within.
    require
        Requirements on outputs, ``"OUTPUT >= VALUE"`` or ``"OUTPUT <= VALUE"`` (``"snr_db >= 30"``,
        ``"dof_m.near <= 1.7"``; the dotted names of `Evaluation`).
    minimize, maximize
        Free keys to make as small / as large as possible: one objective, or two for the Pareto front (minimized
        keys first).
    posterior
        A `Fit` (or a fit directory): the requirements must hold with probability `confidence` (default 0.9) over
        its calibrated posterior.

    Returns
    -------
    pandas.DataFrame
        The Pareto front (one row with one objective): the free keys, the flattened outputs, ``active`` (the
        requirements a 1 % change breaks), ``minimal``, ``pareto`` (and ``probability`` with a posterior); the
        solver's full answer in ``frame.attrs["answer"]``. Raises `Infeasible` when no values meet the
        requirements.

    Examples
    --------
    >>> import uwlab
    >>> design = uwlab.load_design(uwlab.config_path("design/example.toml"))
    >>> best = uwlab.solve(design, free={"light.luminous_flux_lm": (100, 100000)}, require=["snr_db >= 30"],
    ...                    minimize="light.luminous_flux_lm")
    >>> round(float(best["snr_db"].iloc[0]), 2), bool(best["minimal"].iloc[0]), best["active"].iloc[0]
    (30.0, True, 'snr_db >= 30')
    """
    from uwlab.experiments.design.solve import FreeKey, Objective, Problem, front_frame, parse_requirement, result_dict
    from uwlab.experiments.design.solve import solve as run

    senses = [("minimize", k) for k in ([minimize] if isinstance(minimize, str) else minimize)]
    senses += [("maximize", k) for k in ([maximize] if isinstance(maximize, str) else maximize)]
    objectives = [Objective(_dotted(key), sense) for sense, key in senses]
    if confidence is not None and posterior is None:
        raise ConfigError("confidence", confidence, "needs a posterior")
    loader = None
    if posterior is not None:
        from uwlab.experiments.design.posterior import load_posterior

        fit_dir = _posterior_dir(posterior)

        def loader(d: Design) -> Any:
            return load_posterior(fit_dir, d, max_samples=500)

    chosen = 0.9 if confidence is None and posterior is not None else confidence or 1.0
    problem = Problem(
        _raw(design),
        design.base_dir,
        [FreeKey(_dotted(k), float(lo), float(hi)) for k, (lo, hi) in free.items()],
        [parse_requirement(r) for r in require],
        objectives,
        loader,
        chosen,
    )
    result = run(problem)
    answer = result_dict(result, problem)
    if not result.feasible:
        unmet = [entry["requirement"] for entry in answer["unmet"]]
        reason = (
            f"cannot be met even at the bounds: {', '.join(unmet)}"
            if unmet
            else "cannot be met together: " + " | ".join("; ".join(group) for group in answer["conflicting"])
        )
        raise Infeasible(f"no feasible design: {reason}", answer)
    frame = front_frame(result, problem)
    frame.attrs["answer"] = answer
    return frame
