"""Single-bit flips in a dataset's files, and what uwlab makes of each (the integrity campaign of issue 25).

`flip_campaign(pristine, trials, rng)` copies a recorded dataset, flips one random bit of one of its files (each file
equally likely, each bit of it equally likely), then reads the copy as a user would and sorts the outcome:

- ``intact``: read, and every point, spectrum and metadata value equals the pristine dataset's (the flip was
  repaired on the fly from a sealed copy, or struck a byte no reader uses);
- ``refused``: opening or reading raised a one-line `UwlabError`;
- ``silent``: read without complaint but some value differs — the failure this campaign exists to find.

Whatever happened, ``uwlab dataset check --repair`` then runs (in process) and the copy is read again: every point
of every part the flip did not strike must still be there, unchanged (``lost_intact`` counts those that are not),
and a second check must pass.
"""

from __future__ import annotations

import shutil
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from uwlab.errors import UwlabError
from uwlab.experiments.acquisition.dataset_check import check, repair
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.emva.simulate import simulate_photon_transfer
from uwlab.model.sensor import load_sensor_profile
from uwlab.sim.devices.camera import SimTruth


def small_dataset(root: Path) -> Path:
    """A small recorded dataset at ``root``: a simulated photon transfer of a 32 × 32 IMX250, 24 points with their
    spectra in 9 parts (metadata, manifest, their copies and 18 part files)."""
    truth = SimTruth.from_sensor_profile(load_sensor_profile("imx250m"), resolution_px=(32, 32))
    simulate_photon_transfer(
        root,
        truth,
        rate_e_per_s=1.07e5,
        quantum_efficiency=0.6,
        exposures_us=np.linspace(3e3, 120e3, 24),
        frames=2,
        seed=5,
    )
    return root


@dataclass
class Outcomes:
    counts: Counter = field(default_factory=Counter)
    by_file: Counter = field(default_factory=Counter)
    silent: list[str] = field(default_factory=list)
    lost_intact: list[str] = field(default_factory=list)
    unrepaired: list[str] = field(default_factory=list)


def _files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*") if p.is_file() and p.stat().st_size > 0)


def _snapshot(root: Path) -> tuple[pd.DataFrame, pd.DataFrame, dict]:
    dataset = Dataset.open(root)
    return dataset.points(), dataset.spectra(), dataset.metadata


def _same(a: tuple[pd.DataFrame, pd.DataFrame, dict], b: tuple[pd.DataFrame, pd.DataFrame, dict]) -> bool:
    return a[0].equals(b[0]) and a[1].equals(b[1]) and a[2] == b[2]


def _rows(points: pd.DataFrame) -> dict[tuple[str, int], pd.Series]:
    return {(row["sweep_id"], int(row["point_index"])): row for _, row in points.iterrows()}


def flip_campaign(pristine: Path, work: Path, trials: int, rng: np.random.Generator) -> Outcomes:
    """Run ``trials`` flips on copies of ``pristine`` (a dataset) inside ``work``; see the module docstring."""
    reference = _snapshot(pristine)
    reference_rows = _rows(reference[0])
    part_of = {}
    for part in Dataset.open(pristine).store.parts:
        keys = set(
            zip(
                *[
                    Dataset.open(pristine).store.read(part, "points").column(k).to_pylist()
                    for k in ("sweep_id", "point_index")
                ],
                strict=True,
            )
        )
        for table in part.tables.values():
            part_of[table.file] = keys
    outcomes = Outcomes()
    files = [p.relative_to(pristine) for p in _files(pristine)]
    for trial in range(trials):
        copy = work / f"flip-{trial}"
        shutil.copytree(pristine, copy)
        name = files[rng.integers(len(files))]
        data = bytearray((copy / name).read_bytes())
        bit = int(rng.integers(len(data) * 8))
        data[bit // 8] ^= 1 << (bit % 8)
        (copy / name).write_bytes(bytes(data))
        where = f"{name.as_posix()} bit {bit}"
        outcomes.by_file[name.parent.as_posix() if name.parent.name == "parts" else name.name] += 1
        try:
            outcome = "intact" if _same(_snapshot(copy), reference) else "silent"
        except UwlabError:
            outcome = "refused"
        outcomes.counts[outcome] += 1
        if outcome == "silent":
            outcomes.silent.append(where)
        try:
            with Dataset.open_for_writing(copy, "repair") as dataset:
                repair(dataset)
            after = Dataset.open(copy)
            still = _rows(after.points())
            if not check(after).ok:
                outcomes.unrepaired.append(f"{where}: {check(after).problems[0]}")
        except UwlabError as exc:
            outcomes.unrepaired.append(f"{where}: {exc}")
            still = {}
        struck = part_of.get(name.as_posix(), set())
        for key, row in reference_rows.items():
            if key not in struck and (key not in still or not still[key].equals(row)):
                outcomes.lost_intact.append(f"{where}: point {key[0]}#{key[1]}")
        shutil.rmtree(copy)
    return outcomes
