"""The sweep dataset: a directory of tidy tables shared by sweeps, EMVA 1288 analysis and model fits.

Layout (docs/sweeps.md, "Dataset contract"):

- ``points.parquet``: one row per completed point, columns `POINT_SCHEMA` (SI / unit-suffixed, nullable
  where not applicable);
- ``spectra.parquet``: long format, one row per wavelength of each spectrometer reading (`SPECTRA_SCHEMA`);
- ``metadata.json``: the plan and its hash, device identities, resolved rigs, host, times, software versions;
- optionally ``frames/`` with TIFFs.

Durability: every write goes to a temporary file in the dataset directory, is flushed and fsync'ed, then
atomically renamed over the old file (``os.replace``, POSIX rename semantics), so a crash at any moment
leaves the previous, readable version. Spectra are written before their point; spectra of a point that
never completed are ignored on reading and replaced when the point is measured again. A failed write
(e.g. ``ENOSPC``, disk full) raises `DatasetWriteError`; what was already recorded stays intact.
"""
from __future__ import annotations

import json
import os
import platform
import shutil
import socket
import tempfile
from datetime import datetime, timezone
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from uwlab import __version__
from uwlab.errors import ConfigError, UwlabError
from uwlab.experiments.emva.stream import StackStatistics
from uwlab.experiments.saturation import POINT_SATURATED_FRACTION, ClipLevel, point_saturated
from uwlab.jsonable import dumps

POINTS_FILE = "points.parquet"
SPECTRA_FILE = "spectra.parquet"
METADATA_FILE = "metadata.json"
FRAMES_DIR = "frames"
DATASET_ENTRIES = (POINTS_FILE, SPECTRA_FILE, METADATA_FILE, FRAMES_DIR)
KINDS = ("exposure", "aperture", "gain", "light-level", "dark")
SOFTWARE_PACKAGES = ("numpy", "scipy", "pandas", "pyarrow", "colour-science", "opencv-contrib-python-headless",
                     "harvesters", "genicam", "pyserial", "tifffile", "emcee")

POINT_SCHEMA = pa.schema([
    ("sweep_id", pa.string()), ("point_index", pa.int64()), ("kind", pa.string()),
    ("camera_backend", pa.string()), ("camera_id", pa.string()), ("camera_model", pa.string()),
    ("sensor_profile", pa.string()), ("lens_label", pa.string()),
    ("focal_length_mm", pa.float64()), ("f_number", pa.float64()),
    ("exposure_us", pa.float64()), ("gain_db", pa.float64()), ("black_level_dn", pa.float64()),
    ("light_level", pa.float64()), ("light_on", pa.bool_()),
    ("frames", pa.int64()), ("bit_depth", pa.int64()),
    ("roi_x", pa.int64()), ("roi_y", pa.int64()), ("roi_w", pa.int64()), ("roi_h", pa.int64()),
    ("mean_dn", pa.float64()), ("temporal_var_dn2", pa.float64()), ("spatial_var_dn2", pa.float64()),
    ("dark_mean_dn", pa.float64()), ("dark_temporal_var_dn2", pa.float64()), ("dark_spatial_var_dn2", pa.float64()),
    ("dark_frames", pa.int64()), ("signal_dn", pa.float64()),
    ("saturated_fraction", pa.float64()), ("saturated", pa.bool_()),
    ("clip_level_dn", pa.float64()), ("clip_source", pa.string()),
    ("exposure_us_readback", pa.float64()), ("gain_db_readback", pa.float64()), ("temperature_c", pa.float64()),
    ("irradiance_w_m2", pa.float64()), ("irradiance_position", pa.string()),
    ("t_start_ns", pa.int64()), ("t_end_ns", pa.int64()), ("frame_ids", pa.list_(pa.int64())),
])
SPECTRA_SCHEMA = pa.schema([
    ("sweep_id", pa.string()), ("point_index", pa.int64()), ("position", pa.string()),
    ("wavelength_nm", pa.float64()), ("irradiance_w_m2_nm", pa.float64()),
])
REQUIRED_POINT_KEYS = ("sweep_id", "point_index", "kind", "frames")
KEY = ["sweep_id", "point_index"]


class DatasetWriteError(UwlabError):
    """Writing to the dataset failed (disk full, permissions); everything recorded before is intact."""


def software_versions() -> dict[str, str]:
    """Versions of Python and of the installed packages uwlab depends on (absent ones omitted)."""
    versions = {"python": platform.python_version()}
    for name in SOFTWARE_PACKAGES:
        try:
            versions[name] = importlib_metadata.version(name)
        except importlib_metadata.PackageNotFoundError:
            continue
    return versions


def utc_now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def check_point_row(row: dict) -> dict:
    """A point row with every `POINT_SCHEMA` column (missing ones null); unknown or missing required keys
    raise `ConfigError` naming the key."""
    for key in row:
        if key not in POINT_SCHEMA.names:
            raise ConfigError(f"point.{key}", row[key], "unknown dataset column")
    for key in REQUIRED_POINT_KEYS:
        if row.get(key) is None:
            raise ConfigError(f"point.{key}", None, "required")
    if row["kind"] not in KINDS:
        raise ConfigError("point.kind", row["kind"], f"must be one of {', '.join(KINDS)}")
    if int(row["frames"]) < 2:
        raise ConfigError("point.frames", row["frames"], "must be >= 2 (temporal variance needs frame pairs)")
    return {name: row.get(name) for name in POINT_SCHEMA.names}


def point_row(*, sweep_id: str, point_index: int, kind: str, bright: StackStatistics, dark: StackStatistics | None,
              clip: ClipLevel, saturation_threshold: float = POINT_SATURATED_FRACTION, **columns: Any) -> dict:
    """The dataset row of one measured point — the one place a row is built.

    From the point's bright and dark stacks (`uwlab.experiments.emva.stream`) come ``frames``, ``mean_dn``,
    ``temporal_var_dn2``, ``spatial_var_dn2``, the ``dark_*`` columns and ``signal_dn = mean_dn − dark_mean_dn``
    (null without dark frames); from the clip level and the one saturation rule (`uwlab.experiments.saturation`)
    ``saturated_fraction``, ``saturated``, ``clip_level_dn`` and ``clip_source``. ``columns`` are the settings and
    identity columns of `POINT_SCHEMA` (camera, lens, exposure, read-backs, irradiance, times, ...); a column
    given twice, an unknown column or a missing required one raises `ConfigError` naming it.
    """
    derived = {
        "frames": bright.frames, "mean_dn": bright.mean_dn, "temporal_var_dn2": bright.temporal_var_dn2,
        "spatial_var_dn2": bright.spatial_var_dn2,
        "dark_mean_dn": dark.mean_dn if dark else None,
        "dark_temporal_var_dn2": dark.temporal_var_dn2 if dark else None,
        "dark_spatial_var_dn2": dark.spatial_var_dn2 if dark else None,
        "dark_frames": dark.frames if dark else 0,
        "signal_dn": bright.mean_dn - dark.mean_dn if dark else None,
        "saturated_fraction": bright.saturated_fraction,
        "saturated": point_saturated(bright.saturated_fraction, saturation_threshold),
        "clip_level_dn": clip.dn, "clip_source": clip.source,
    }
    twice = sorted(set(derived) & set(columns))
    if twice:
        raise ConfigError(f"point.{twice[0]}", columns[twice[0]], "derived from the frame statistics; do not pass it")
    return check_point_row({"sweep_id": sweep_id, "point_index": point_index, "kind": kind, **derived, **columns})


def spectra_frame(sweep_id: str, point_index: int, readings: list[tuple[str, Any, Any]]) -> pd.DataFrame:
    """Long-format spectra rows of one point from ``[(position, wavelength_nm, irradiance_w_m2_nm), ...]``."""
    parts = [pd.DataFrame({"sweep_id": sweep_id, "point_index": int(point_index), "position": position,
                           "wavelength_nm": pd.Series(wavelength, dtype=float),
                           "irradiance_w_m2_nm": pd.Series(irradiance, dtype=float)})
             for position, wavelength, irradiance in readings]
    if not parts:
        return SPECTRA_SCHEMA.empty_table().to_pandas()
    return pd.concat(parts, ignore_index=True)


def _write_atomic(path: Path, write) -> None:
    """Write through ``write(tmp_path)`` to a temporary sibling, fsync, then rename over ``path``."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise DatasetWriteError(
            f"dataset {path.parent}: cannot write {path.name} ({exc.strerror or exc}); "
            "everything recorded before is intact: free space, then --resume"
        ) from exc
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _write_parquet(path: Path, table: pa.Table) -> None:
    _write_atomic(path, lambda tmp: pq.write_table(table, tmp))


def _write_json(path: Path, document: dict) -> None:
    def write(tmp: str) -> None:
        with open(tmp, "w") as fh:
            fh.write(dumps(document, indent=2))
            fh.write("\n")
    _write_atomic(path, write)


def _read_table(path: Path, schema: pa.Schema) -> pa.Table:
    if not path.exists():
        return schema.empty_table()
    try:
        return pq.read_table(path, schema=schema)
    except (OSError, pa.ArrowInvalid) as exc:
        raise ConfigError("dataset", str(path), f"unreadable table ({exc})") from None


class Dataset:
    """A dataset directory: create it, open it, append points one at a time (each flushed atomically)."""

    def __init__(self, root: Path, metadata: dict, points: pa.Table, spectra: pa.Table):
        self.root = root
        self.metadata = metadata
        self._points = points
        self._spectra = spectra

    # -- creation and opening ---------------------------------------------------------------------
    @classmethod
    def create(cls, root: str | os.PathLike, plan: dict, *, plan_sha256: str, devices: dict | None = None,
               rigs: dict | None = None, sim: bool = False, sim_truth: dict | None = None,
               force: bool = False) -> Dataset:
        """A new, empty dataset at ``root``. An existing dataset there is refused (`ConfigError` on ``out``)
        unless ``force``, which removes only the dataset's own entries (`DATASET_ENTRIES`)."""
        root = Path(root)
        existing = [name for name in DATASET_ENTRIES if (root / name).exists()]
        if existing and not force:
            raise ConfigError("out", str(root), "a dataset exists there; use --resume to complete it or --force "
                                                "to overwrite it")
        if root.exists() and not root.is_dir():
            raise ConfigError("out", str(root), "exists and is not a directory")
        try:
            root.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DatasetWriteError(f"dataset {root}: cannot create the directory ({exc.strerror or exc})") from exc
        for name in existing:
            _remove(root / name)
        metadata = {
            "plan": plan, "plan_sha256": plan_sha256, "uwlab_version": __version__,
            "devices": devices or {}, "rigs": rigs or {}, "host": socket.gethostname(),
            "started_utc": utc_now(), "finished_utc": None, "software": software_versions(),
            "sim": bool(sim), "sim_truth": sim_truth or {},
        }
        dataset = cls(root, metadata, POINT_SCHEMA.empty_table(), SPECTRA_SCHEMA.empty_table())
        dataset._save_metadata()
        _write_parquet(root / POINTS_FILE, dataset._points)
        _write_parquet(root / SPECTRA_FILE, dataset._spectra)
        return dataset

    @classmethod
    def open(cls, root: str | os.PathLike) -> Dataset:
        root = Path(root)
        meta_path = root / METADATA_FILE
        try:
            metadata = json.loads(meta_path.read_text())
        except FileNotFoundError:
            raise ConfigError("dataset", str(root), f"not a dataset (no {METADATA_FILE})") from None
        except (OSError, ValueError) as exc:
            raise ConfigError("dataset", str(root), f"unreadable {METADATA_FILE} ({exc})") from None
        if not isinstance(metadata, dict) or "plan_sha256" not in metadata:
            raise ConfigError("dataset", str(root), f"{METADATA_FILE} has no plan_sha256")
        return cls(root, metadata, _read_table(root / POINTS_FILE, POINT_SCHEMA),
                   _read_table(root / SPECTRA_FILE, SPECTRA_SCHEMA))

    # -- writing ----------------------------------------------------------------------------------
    def append_point(self, row: dict, spectra: pd.DataFrame | None = None) -> None:
        """Record one completed point (and its spectra, long format) durably before returning.

        A point already recorded (same sweep_id and point_index) is refused: resuming must skip it."""
        row = check_point_row(row)
        key = (row["sweep_id"], int(row["point_index"]))
        if key in self.completed():
            raise ConfigError("point", f"{key[0]}#{key[1]}", "already recorded in this dataset")
        if spectra is not None and len(spectra):
            kept = self._spectra_without(key)
            new = pa.Table.from_pandas(spectra[SPECTRA_SCHEMA.names], schema=SPECTRA_SCHEMA, preserve_index=False)
            table = pa.concat_tables([kept, new])
            _write_parquet(self.root / SPECTRA_FILE, table)
            self._spectra = table
        points = pa.concat_tables([self._points, pa.Table.from_pylist([row], schema=POINT_SCHEMA)])
        _write_parquet(self.root / POINTS_FILE, points)
        self._points = points

    def update_metadata(self, **changes: Any) -> None:
        """Merge top-level keys into metadata.json (atomically); dict values are merged one level deep."""
        for key, value in changes.items():
            current = self.metadata.get(key)
            self.metadata[key] = {**current, **value} if isinstance(current, dict) and isinstance(value, dict) else value
        self._save_metadata()

    def finish(self) -> None:
        self.update_metadata(finished_utc=utc_now())

    def _save_metadata(self) -> None:
        _write_json(self.root / METADATA_FILE, self.metadata)

    def _spectra_without(self, key: tuple[str, int]) -> pa.Table:
        frame = self._spectra.to_pandas()
        keep = ~((frame["sweep_id"] == key[0]) & (frame["point_index"] == key[1]))
        return pa.Table.from_pandas(frame[keep], schema=SPECTRA_SCHEMA, preserve_index=False)

    # -- reading ----------------------------------------------------------------------------------
    def points(self) -> pd.DataFrame:
        """Completed points, one row each, in recording order (nullable columns as pandas NA/None)."""
        return self._points.to_pandas()

    def spectra(self) -> pd.DataFrame:
        """Spectra of completed points only (readings of a point interrupted before completion are dropped)."""
        frame = self._spectra.to_pandas()
        done = self.points()[KEY].drop_duplicates()
        return frame.merge(done, on=KEY, how="inner")

    def completed(self) -> set[tuple[str, int]]:
        """``{(sweep_id, point_index)}`` of the recorded points."""
        table = self._points.select(KEY).to_pydict()
        return set(zip(table["sweep_id"], table["point_index"]))

    @property
    def plan_sha256(self) -> str:
        return self.metadata["plan_sha256"]


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink()


def summarize(dataset: Dataset) -> dict:
    """A JSON-able summary: per sweep points done/total and saturated, time span, devices, plan hash."""
    from uwlab.experiments.acquisition.plan import point_counts

    meta = dataset.metadata
    points = dataset.points()
    totals = point_counts(meta.get("plan", {}))
    sweeps = []
    for sweep_id, total in totals.items():
        rows = points[points["sweep_id"] == sweep_id]
        sweeps.append({"id": sweep_id, "kind": rows["kind"].iloc[0] if len(rows) else None,
                       "points_done": int(len(rows)), "points_total": int(total),
                       "saturated_points": int(rows["saturated"].fillna(False).astype(bool).sum()),
                       "sensor_profile": rows["sensor_profile"].iloc[0] if len(rows) else None,
                       "lens_label": rows["lens_label"].iloc[0] if len(rows) else None})
    span = None
    if len(points):
        span = {"start_utc": _iso_ns(int(points["t_start_ns"].min())), "end_utc": _iso_ns(int(points["t_end_ns"].max()))}
    return {
        "path": str(dataset.root), "plan_name": meta.get("plan", {}).get("name"), "plan_sha256": meta["plan_sha256"],
        "sim": meta.get("sim"), "started_utc": meta.get("started_utc"), "finished_utc": meta.get("finished_utc"),
        "points_done": int(len(points)), "points_total": int(sum(totals.values())),
        "saturated_points": int(sum(s["saturated_points"] for s in sweeps)), "time_span": span,
        "spectra_rows": int(len(dataset.spectra())), "sweeps": sweeps, "devices": meta.get("devices", {}),
    }


def _iso_ns(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, timezone.utc).isoformat(timespec="seconds")
