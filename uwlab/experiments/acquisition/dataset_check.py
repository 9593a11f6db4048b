"""Checking, repairing and summarising a dataset (``uwlab dataset check``, ``uwlab dataset show``).

`check` reads every part of a dataset and reports each `Problem`:

- a part file missing, differing from the SHA-256 the manifest records, unreadable (Parquet page checksums), with
  other rows than the manifest says or columns outside the schema;
- a point row breaking the one row rule (`uwlab.experiments.dataset.check_point_row`: unknown kind, required
  column missing, fewer than 2 frames, a NaN or infinite number);
- a point recorded twice, or one the plan in ``metadata.json`` does not have (unknown sweep, index past its values);
- spectra of no point of their part, or a reading whose wavelengths are not strictly increasing;
- a point of a ``save_frames`` sweep without all its frames (``frames`` bright and ``dark_frames`` dark);
- ``finished_utc`` set while points are missing;
- a damaged copy of ``metadata.json`` or ``manifest.json`` (each is sealed with its checksum and kept twice,
  `uwlab.experiments.dataset_store.write_sealed`; the dataset was read from the intact copy).

What cannot be repaired (no readable ``metadata.json`` or manifest, a plan whose points cannot be counted) is
raised as `ConfigError` by opening or reported as a problem that `repair` refuses.

`repair` (under the dataset's lock) never deletes: every damaged or rewritten part file is linked (or copied) into
``quarantine/<UTC time>/`` first, rows that break the rules leave the dataset (their parts are rewritten with
the other rows), frame folders of points no longer recorded move there too, and a wrong ``finished_utc`` is
cleared; a damaged copy of the metadata or the manifest is rewritten from the intact one (the damaged file kept in
the quarantine folder). ``uwlab sweep --resume`` then measures exactly the points set aside.
"""

from __future__ import annotations

import os
import shutil
from collections import Counter
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa

from uwlab.errors import ConfigError, UwlabError
from uwlab.experiments.dataset import KEY, POINT_SCHEMA, QUARANTINE_DIR, Dataset, check_point_row
from uwlab.experiments.dataset_frames import FRAMES_DIR, point_frames, stored_point_folders, sweep_folder
from uwlab.experiments.dataset_store import PartDamaged
from uwlab.outputs import MANIFEST_FILE, METADATA_FILE
from uwlab.jsonable import dumps


@dataclass(frozen=True)
class Problem:
    """Something wrong with a dataset: where (a file or a point) and what."""

    where: str
    what: str

    def __str__(self) -> str:
        return f"{self.where}: {self.what}"


@dataclass
class CheckReport:
    """The outcome of `check`. ``points``: the rows that pass, in recording order; ``totals``: points per sweep in
    the plan (None when the plan's points cannot be counted); ``damaged_parts``: ids of parts with a damaged file;
    ``set_aside``: part id → keys of its rows that break the rules; ``orphan_spectra``: ids of parts holding spectra
    of none of their points; ``strays``: files no committed state names (removed by the next writer)."""

    root: Path
    problems: list[Problem] = field(default_factory=list)
    points: pd.DataFrame = field(default_factory=lambda: POINT_SCHEMA.empty_table().to_pandas())
    totals: dict[str, int] | None = None
    damaged_parts: set[int] = field(default_factory=set)
    set_aside: dict[int, set[tuple[str, int]]] = field(default_factory=dict)
    orphan_spectra: set[int] = field(default_factory=set)
    finished_early: bool = False
    damaged_copies: list[Path] = field(default_factory=list)
    strays: list[Path] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    @property
    def repairable(self) -> bool:
        return self.totals is not None

    def summary_line(self) -> str:
        """One line: the first problem and how many more."""
        more = f" (and {len(self.problems) - 1} more)" if len(self.problems) > 1 else ""
        return f"{self.problems[0]}{more}" if self.problems else "ok"


def check(dataset: Dataset) -> CheckReport:
    """Verify every part, row, spectrum and frame folder of ``dataset`` (see the module docstring)."""
    from uwlab.experiments.acquisition.plan import point_counts, sweep_tables

    report = CheckReport(dataset.root, strays=dataset.store.stray_files())
    for name, problems in ((METADATA_FILE, dataset.metadata_problems), (MANIFEST_FILE, dataset.store.copy_problems)):
        for problem in problems:
            damaged = problem.split(" ", 1)[0]
            report.damaged_copies.append(dataset.root / damaged)
            report.problems.append(
                Problem(
                    damaged,
                    f"{problem.split(' ', 1)[1]}; the dataset was read from the "
                    f"other copy of {name}: --repair rewrites this one from it",
                )
            )
    try:
        report.totals = point_counts(dataset.metadata.get("plan", {}))
        save_frames = {
            sweep_id: body.get("save_frames") is True
            for sweep_id, body in sweep_tables(dataset.metadata.get("plan", {})).items()
        }
    except ConfigError as exc:
        report.problems.append(Problem("metadata.json", f"the plan's points cannot be counted ({exc}); not repairable"))
        save_frames = {}
    parts = []
    for part in dataset.store.parts:
        rows = _check_part(dataset, part, report)
        if rows is not None:
            parts.append((part, rows))
    counts = Counter(key for _, rows in parts for key in rows)
    good = []
    for part, rows in parts:
        for key, row in rows.items():
            if key in report.set_aside.get(part.id, ()):
                continue  # already reported by _check_part
            reason = _row_problem(dataset, row, counts[key], report.totals, save_frames)
            if reason is not None:
                report.set_aside.setdefault(part.id, set()).add(key)
                report.problems.append(Problem(f"point {key[0]}#{key[1]}", reason))
            else:
                good.append(row)
    report.points = pa.Table.from_pylist(good, schema=POINT_SCHEMA).to_pandas()
    missing = _missing(report)
    if dataset.metadata.get("finished_utc") and missing:
        report.finished_early = True
        report.problems.append(Problem("metadata.json", f"finished_utc is set but {missing} points are missing"))
    return report


def _check_part(dataset: Dataset, part, report: CheckReport) -> dict[tuple[str, int], dict] | None:
    """The rows of one part by key (the last of a key within it), or None when a file of the part is damaged."""
    store = dataset.store
    try:
        points = store.read(part, "points")
        spectra = store.read(part, "spectra")
    except (PartDamaged, FileNotFoundError) as exc:
        file, reason = (exc.file, exc.reason) if isinstance(exc, PartDamaged) else (Path(exc.filename).name, "missing")
        report.damaged_parts.add(part.id)
        report.problems.append(
            Problem(
                file,
                f"{reason}; its {part.rows('points')} points will be set aside by "
                "--repair and measured again by --resume",
            )
        )
        return None
    rows = {}
    for row in points.to_pylist():
        rows[(row["sweep_id"], row["point_index"])] = row
    where = ", ".join(f.file for f in part.tables.values())
    frame = spectra.to_pandas()
    for (sweep_id, index, position), reading in frame.groupby(["sweep_id", "point_index", "position"], sort=False):
        key = (sweep_id, int(index))
        if key not in rows:
            report.orphan_spectra.add(part.id)
            report.problems.append(Problem(where, f"spectra of {sweep_id}#{index}, a point this part does not hold"))
            continue
        nm, values = reading["wavelength_nm"].to_numpy(), reading["irradiance_w_m2_nm"].to_numpy()
        if not (np.isfinite(nm).all() and np.isfinite(values).all() and np.all(np.diff(nm) > 0)):
            report.set_aside.setdefault(part.id, set()).add(key)
            report.problems.append(
                Problem(
                    f"point {sweep_id}#{index}",
                    f"spectrum at {position}: wavelengths not strictly increasing or values not finite",
                )
            )
    if len(rows) != points.num_rows:
        counts = Counter(
            zip(points.column("sweep_id").to_pylist(), points.column("point_index").to_pylist(), strict=True)
        )
        for key, count in counts.items():
            if count > 1:
                report.set_aside.setdefault(part.id, set()).add(key)
                report.problems.append(Problem(f"point {key[0]}#{key[1]}", f"recorded {count} times in {where}"))
    return rows


def _row_problem(
    dataset: Dataset, row: dict, copies: int, totals: dict[str, int] | None, save_frames: dict[str, bool]
) -> str | None:
    key = (row["sweep_id"], row["point_index"])
    if copies > 1:
        return f"recorded {copies} times (in several parts)"
    try:
        check_point_row(row)
    except ConfigError as exc:
        return str(exc)
    if totals is not None and not 0 <= key[1] < totals.get(key[0], 0):
        return (
            f"not in the plan (sweep {key[0]!r} has {totals[key[0]]} points)"
            if key[0] in totals
            else f"not in the plan (no sweep {key[0]!r})"
        )
    if save_frames.get(key[0]):
        frames = point_frames(dataset.root, *key)
        if len(frames.bright) != row["frames"] or len(frames.dark) != (row["dark_frames"] or 0):
            return (
                f"has {len(frames.bright)}/{row['frames']} bright and {len(frames.dark)}/{row['dark_frames'] or 0} "
                "dark frames stored (save_frames = true)"
            )
    return None


def _missing(report: CheckReport) -> int:
    if report.totals is None:
        return 0
    done = Counter(report.points["sweep_id"])
    return sum(max(total - done.get(sweep_id, 0), 0) for sweep_id, total in report.totals.items())


def repair(dataset: Dataset) -> list[str]:
    """Set aside what fails `check` (see the module docstring); returns what was done, one line each. The dataset
    must be open for writing; `UwlabError` when the problem is not repairable."""
    report = check(dataset)
    if report.ok:
        return []
    if not report.repairable:
        raise UwlabError(f"dataset {dataset.root}: cannot repair: {report.problems[0]}")
    store = dataset.store
    quarantine = _quarantine_folder(dataset.root)
    done = []
    if report.damaged_copies:
        for path in report.damaged_copies:
            if path.exists():
                _link_or_copy(path, quarantine / path.name)
        dataset.restore_copies()
        done.append(f"rewrote {', '.join(p.name for p in report.damaged_copies)} from the intact copies")
    changes: dict[int, dict[str, pa.Table] | None] = {}
    for part in store.parts:
        files = ", ".join(f.file for f in part.tables.values())
        if part.id in report.damaged_parts:
            changes[part.id] = None
            done.append(f"set aside {files} (damaged): its {part.rows('points')} points leave the dataset")
        elif part.id in report.set_aside or part.id in report.orphan_spectra:
            keys = report.set_aside.get(part.id, set())
            changes[part.id] = _without(store.read(part, "points"), store.read(part, "spectra"), keys)
            done.append(
                f"rewrote {files} without {len(keys)} points "
                f"({', '.join(f'{s}#{i}' for s, i in sorted(keys)) or 'stray spectra only'})"
            )
    keep = set(zip(report.points["sweep_id"], report.points["point_index"], strict=True))
    for key, folder in stored_point_folders(dataset.root).items():
        if key not in keep:
            target = quarantine / FRAMES_DIR / sweep_folder(key[0]) / folder.name
            target.parent.mkdir(parents=True, exist_ok=True)
            os.rename(folder, target)
            done.append(f"moved the frames of {key[0]}#{key[1]} (not recorded) aside")
    for path in (dataset.root / f.file for p in store.parts if p.id in changes for f in p.tables.values()):
        if path.exists():
            _link_or_copy(path, quarantine / path.relative_to(dataset.root))
    for path in store.replace(changes):
        path.unlink(missing_ok=True)
    if report.finished_early:
        dataset.update_metadata(finished_utc=None)
        done.append("cleared finished_utc: points are missing")
    (quarantine / "repair.json").write_text(
        dumps({"problems": [str(p) for p in report.problems], "actions": done}, indent=2) + "\n"
    )
    done.append(
        f"originals and a record of this repair are in {quarantine}; measure the points set aside with "
        f"`uwlab sweep PLAN --resume {dataset.root}`"
    )
    return done


def _without(points: pa.Table, spectra: pa.Table, keys: set[tuple[str, int]]) -> dict[str, pa.Table]:
    """A part's tables without the points ``keys`` and without spectra of points it does not keep."""
    frame = points.to_pandas()
    kept = frame[[(s, i) not in keys for s, i in zip(frame["sweep_id"], frame["point_index"], strict=True)]]
    kept_keys = kept[KEY].drop_duplicates()
    spectra_kept = spectra.to_pandas().merge(kept_keys, on=KEY, how="inner")
    return {
        "points": pa.Table.from_pandas(kept, schema=POINT_SCHEMA, preserve_index=False),
        "spectra": pa.Table.from_pandas(spectra_kept, schema=spectra.schema, preserve_index=False),
    }


def _quarantine_folder(root: Path) -> Path:
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    folder, number = root / QUARANTINE_DIR / stamp, 1
    while folder.exists():
        number += 1
        folder = root / QUARANTINE_DIR / f"{stamp}-{number}"
    folder.mkdir(parents=True)
    return folder


def _link_or_copy(source: Path, target: Path) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(source, target)
    except OSError:
        shutil.copy2(source, target)


def summarize(dataset: Dataset) -> dict:
    """A JSON-able summary from a full `check`: ``state`` ("complete", "incomplete", "empty" or "damaged"), per
    sweep points done (passing the check) / total (in the plan) and saturated, time span, devices, plan hash and
    the problems found."""
    report = check(dataset)
    meta, points, totals = dataset.metadata, report.points, report.totals or {}
    sweeps = []
    saturated_points = 0
    for sweep_id, total in totals.items():
        rows = points[points["sweep_id"] == sweep_id]
        saturated = int(rows["saturated"].fillna(False).astype(bool).sum())
        saturated_points += saturated
        sweeps.append(
            {
                "id": sweep_id,
                "kind": rows["kind"].iloc[0] if len(rows) else None,
                "points_done": int(len(rows)),
                "points_total": int(total),
                "saturated_points": saturated,
                "sensor_profile": rows["sensor_profile"].iloc[0] if len(rows) else None,
                "lens_label": rows["lens_label"].iloc[0] if len(rows) else None,
            }
        )
    span = None
    if len(points) and points["t_start_ns"].notna().any():
        span = {
            "start_utc": _iso_ns(int(points["t_start_ns"].min())),
            "end_utc": _iso_ns(int(points["t_end_ns"].max())),
        }
    done, total = int(len(points)), int(sum(totals.values()))
    state = "damaged" if not report.ok else "empty" if done == 0 else "complete" if done == total else "incomplete"
    return {
        "path": str(dataset.root),
        "plan_name": meta.get("plan", {}).get("name"),
        "plan_sha256": meta["plan_sha256"],
        "sim": meta.get("sim"),
        "state": state,
        "started_utc": meta.get("started_utc"),
        "finished_utc": meta.get("finished_utc"),
        "points_done": done,
        "points_total": total,
        "saturated_points": saturated_points,
        "time_span": span,
        "spectra_rows": int(sum(p.rows("spectra") for p in dataset.store.parts)),
        "sweeps": sweeps,
        "devices": meta.get("devices", {}),
        "problems": [str(p) for p in report.problems],
    }


def _iso_ns(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, UTC).isoformat(timespec="seconds")
