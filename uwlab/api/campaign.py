"""Sweeps and datasets from Python: `load_plan`, `sweep`, `Dataset` — `uwlab sweep` and `uwlab dataset show`.

>>> import uwlab
>>> plan = uwlab.load_plan(uwlab.config_path("plans/tank-exposure-sweep.toml"))
>>> plan.name, plan.total_points()
('tank-exposure-sweep', 72)
"""

from __future__ import annotations

import os
from collections.abc import Callable
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from uwlab.experiments.acquisition.plan import Plan

if TYPE_CHECKING:
    import pandas as pd

    from uwlab.experiments.acquisition.sweep import Progress
    from uwlab.experiments.dataset import Dataset as Store


def load_plan(path: str | Path) -> Plan:
    """Read and validate a sweep plan (``docs/sweeps.md``; `uwlab.errors.ConfigError` names a bad key). A relative
    path that is not a file here names a bundled plan (``"plans/tank-exposure-sweep.toml"``; `config_file`).

    Examples
    --------
    >>> import uwlab
    >>> plan = uwlab.load_plan(uwlab.config_path("plans/emva-photon-transfer.toml"))
    >>> [(s.table.id, s.table.kind, len(s.values)) for s in plan.sweeps]
    [('photon-transfer', 'exposure', 60), ('dark-current', 'dark', 6)]
    """
    from uwlab.api.paths import config_file
    from uwlab.experiments.acquisition.plan import load_plan as load

    return load(config_file(path, "plan"))


def dataset_path(source: Dataset | str | os.PathLike[str]) -> Path:
    """The directory of a `Dataset`, or a path as a `Path`."""
    return source.path if isinstance(source, Dataset) else Path(source)


class Dataset:
    """A sweep dataset, read-only: ``Dataset.open(path)``; `points` (one row per measured point) and `spectra`
    (long format) as DataFrames, `metadata` (plan, devices, simulated truth), `summary` (``uwlab dataset show``).

    Examples
    --------
    >>> import tempfile, uwlab
    >>> from uwlab.experiments.emva.simulate import simulate_photon_transfer
    >>> from uwlab.model.sensor import load_sensor_profile
    >>> from uwlab.sim.devices.camera import SimTruth
    >>> root = tempfile.mkdtemp() + "/pt"
    >>> truth = SimTruth.from_sensor_profile(load_sensor_profile("imx250m"), resolution_px=(32, 24))
    >>> _ = simulate_photon_transfer(root, truth, rate_e_per_s=1e6, quantum_efficiency=0.6,
    ...                              exposures_us=[100, 200, 400])
    >>> data = uwlab.Dataset.open(root)
    >>> len(data.points), data.points["exposure_us"].tolist()
    (3, [100.0, 200.0, 400.0])
    >>> data.summary["state"]
    'complete'
    """

    def __init__(self, store: Store) -> None:
        self._store = store

    @classmethod
    def open(cls, path: str | os.PathLike[str]) -> Dataset:
        """The dataset at `path` (its last committed state; no lock is taken)."""
        from uwlab.experiments.dataset import Dataset as Store

        return cls(Store.open(path))

    @property
    def path(self) -> Path:
        return Path(self._store.root)

    @property
    def metadata(self) -> dict[str, Any]:
        return dict(self._store.metadata)

    @cached_property
    def points(self) -> pd.DataFrame:
        """The measured points, one row each, in recording order (columns: docs/sweeps.md)."""
        return self._store.points()

    @cached_property
    def spectra(self) -> pd.DataFrame:
        """The spectra of the points: sweep_id, point_index, position, wavelength_nm, irradiance_w_m2_nm."""
        return self._store.spectra()

    @cached_property
    def summary(self) -> dict[str, Any]:
        """State (complete, incomplete, empty, damaged), points done and saturated per sweep, devices, time span,
        problems found by the full check (``uwlab dataset show --json``)."""
        from uwlab.experiments.acquisition.dataset_check import summarize

        return summarize(self._store)

    def __repr__(self) -> str:
        return f"Dataset({str(self.path)!r})"


def sweep(
    plan: Plan | str | Path,
    out: str | Path | None = None,
    *,
    sim: bool = False,
    resume: bool = False,
    force: bool = False,
    seed: int = 0,
    progress: bool = True,
    confirm: Callable[[str], None] | None = None,
) -> Dataset:
    """Run a sweep plan into a dataset (``uwlab sweep``), point by point, each durable as it completes.

    Parameters
    ----------
    plan
        A plan (`load_plan`) or its file (a bundled plan by name: ``"plans/tank-exposure-sweep.toml"``).
    out
        The new dataset directory (default ``<plan name>-dataset``), made as ``uwlab sweep --out`` makes it
        (`uwlab.outputs`: its parent directory must exist); with `resume`, the unfinished dataset to complete
        (same plan; its points are skipped).
    sim
        Run on the simulated rig (cameras, light and spectrometer simulated, their noise seeded from `seed`);
        else on the plan's devices.
    force
        Replace an existing dataset at `out`.
    progress
        Show a progress bar (a terminal or a notebook; nothing when stderr is a file).
    confirm
        On the real rig, ``confirm(message)`` asks the operator to do a manual step (set an aperture, move the
        spectrometer); None refuses such steps.

    Returns
    -------
    Dataset
        The dataset, opened for reading. The lights go to their safe state and the simulators stop on any exit;
        an interruption leaves a valid dataset to complete with ``resume=True``.

    Examples
    --------
    >>> import tempfile, uwlab
    >>> data = uwlab.sweep("plans/tank-exposure-sweep.toml", tempfile.mkdtemp() + "/tank", sim=True)  # doctest: +SKIP
    >>> data.summary["points_done"]  # doctest: +SKIP
    72
    """
    from uwlab.api.paths import python_names
    from uwlab.experiments.acquisition.session import progress_text, run_session
    from uwlab.progress import bar

    loaded = plan if isinstance(plan, Plan) else load_plan(plan)
    with python_names(), bar(desc="sweep", unit="point", enabled=progress) as shown:

        def report(event: Progress) -> None:
            shown.total = event.total
            shown.set_position(event.done, progress_text(event))

        root = run_session(
            loaded,
            out,
            resume=resume,
            sim=sim,
            force=force,
            confirm=confirm,
            seed=seed,
            progress=report,
            purpose="uwlab.sweep",
        )
    return Dataset.open(root)
