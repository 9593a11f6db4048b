"""The sweep dataset: a directory of tidy tables shared by sweeps, EMVA 1288 analysis and model fits.

Layout (docs/sweeps.md, "Dataset contract"):

- the ``points`` table: one row per completed point, columns `POINT_SCHEMA` (SI / unit-suffixed, nullable where
  not applicable), built by `point_row` (the one row builder) and checked by `check_point_row` (the one row rule);
- the ``spectra`` table: long format, one row per wavelength of each spectrometer reading (`SPECTRA_SCHEMA`);
- both stored append-only as Parquet parts listed by ``manifest.json`` (`uwlab.experiments.dataset_store`:
  checksums, crash safety, flat cost per point);
- ``metadata.json``: the plan and its hash, device identities, resolved rigs, host, times, and the software and
  machine that recorded it (``provenance``, `uwlab.provenance`; a resumed sweep adds each resuming session's to
  ``resumed``);
- ``frames/``: the raw frames of plans with ``save_frames`` (`uwlab.experiments.dataset_frames`);
- ``lock``: names the one writer (`uwlab.lockfile`); ``quarantine/``: what ``uwlab dataset check --repair`` set
  aside (`uwlab.experiments.acquisition.dataset_check`).

A point is recorded when `Dataset.append_point` returns: its frames, spectra and row are durable together (the
manifest is the commit point), so a crash or SIGKILL at any moment leaves a readable dataset whose recorded
points all resume. Readers (`Dataset.open`) take no lock and see the last committed state; writers
(`Dataset.create`, `Dataset.open_for_writing`) hold the dataset's lock until `Dataset.close`. A failed write
(disk full, read-only) raises `DatasetWriteError`; what was already recorded stays intact.
"""

from __future__ import annotations

import json
import math
import numbers
import os
import shutil
import socket
from datetime import datetime, UTC
from pathlib import Path
from typing import Any, Literal, get_args

import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from uwlab import __version__
from uwlab.errors import ConfigError, UwlabError
from uwlab.experiments.dataset_frames import (
    FRAMES_DIR,
    FrameRecorder,
    PointFrames,
    point_folder,
    point_frames,
    staging_folders,
    stored_point_folders,
    sweep_folder,
)
from uwlab.experiments.dataset_store import (
    MANIFEST_FILE,
    PARTS_DIR,
    DatasetWriteError,
    ManifestDamaged,
    PartStore,
    backup_path,
    read_sealed,
    write_sealed,
)
from uwlab.experiments.frames.esfr import EdgeMTF
from uwlab.experiments.frames.frame import CHANNEL_NAMES
from uwlab.experiments.frames.stack import StackStatistics
from uwlab.experiments.saturation import POINT_SATURATED_FRACTION, ClipLevel, point_saturated
from uwlab.jsonable import dumps
from uwlab.lockfile import LockHeld, OwnerLock
from uwlab.outputs import METADATA_FILE
from uwlab.provenance import provenance

LOCK_FILE = "lock"
QUARANTINE_DIR = "quarantine"
DATASET_ENTRIES = (
    METADATA_FILE,
    MANIFEST_FILE,
    backup_path(Path(METADATA_FILE)).name,
    backup_path(Path(MANIFEST_FILE)).name,
    PARTS_DIR,
    FRAMES_DIR,
    QUARANTINE_DIR,
)
# What a sweep steps, the kind of each point row.
SweepKind = Literal["exposure", "aperture", "gain", "light-level", "dark", "geometry"]
KINDS: tuple[str, ...] = get_args(SweepKind)

# The per-channel columns of a raw Bayer point, ``<channel>_<statistic>`` with the design model's channel names
# (``sensor.channel``: red, green, blue); null for a monochrome point (`point_row`).
CHANNEL_STATISTICS = (
    ("pixels", pa.int64()),
    ("mean_dn", pa.float64()),
    ("temporal_var_dn2", pa.float64()),
    ("spatial_var_dn2", pa.float64()),
    ("dark_mean_dn", pa.float64()),
    ("dark_temporal_var_dn2", pa.float64()),
    ("dark_spatial_var_dn2", pa.float64()),
    ("signal_dn", pa.float64()),
    ("saturated_fraction", pa.float64()),
    ("saturated", pa.bool_()),
    *(
        (f"{prefix}spatial_var_{part}_dn2", pa.float64())
        for prefix in ("", "dark_")
        for part in ("row", "col", "pixel")
    ),
)
CHANNEL_FIELDS = tuple(
    (f"{channel}_{statistic}", kind) for channel in CHANNEL_NAMES.values() for statistic, kind in CHANNEL_STATISTICS
)
# A geometry point's slanted edge (ISO 12233 e-SFR, `uwlab.experiments.frames.esfr`): MTF50 and the MTF at Nyquist
# in cycles per pixel along the edge normal, the edge's angle from the pixel grid; of the whole mosaic (every pixel)
# and, for a raw Bayer point, of each colour channel's own sites (``<channel>_<statistic>``). Null for other points.
EDGE_STATISTICS = (("mtf50_cy_per_px", pa.float64()), ("mtf_nyquist", pa.float64()), ("edge_angle_deg", pa.float64()))
EDGE_FIELDS = (
    ("lens_focus_m", pa.float64()),
    ("target_distance_m", pa.float64()),
    ("geometry_set_by", pa.string()),
    ("edge_roi_x", pa.int64()),
    ("edge_roi_y", pa.int64()),
    ("edge_roi_w", pa.int64()),
    ("edge_roi_h", pa.int64()),
    *EDGE_STATISTICS,
    *((f"{channel}_{statistic}", kind) for channel in CHANNEL_NAMES.values() for statistic, kind in EDGE_STATISTICS),
)
POINT_SCHEMA = pa.schema(
    [
        ("sweep_id", pa.string()),
        ("point_index", pa.int64()),
        ("kind", pa.string()),
        ("camera_backend", pa.string()),
        ("camera_id", pa.string()),
        ("camera_model", pa.string()),
        ("sensor_profile", pa.string()),
        ("lens_label", pa.string()),
        ("focal_length_mm", pa.float64()),
        ("f_number", pa.float64()),
        ("exposure_us", pa.float64()),
        ("gain_db", pa.float64()),
        ("black_level_dn", pa.float64()),
        ("light_level", pa.float64()),
        ("light_on", pa.bool_()),
        ("frames", pa.int64()),
        ("bit_depth", pa.int64()),
        ("roi_x", pa.int64()),
        ("roi_y", pa.int64()),
        ("roi_w", pa.int64()),
        ("roi_h", pa.int64()),
        ("mean_dn", pa.float64()),
        ("temporal_var_dn2", pa.float64()),
        ("spatial_var_dn2", pa.float64()),
        ("dark_mean_dn", pa.float64()),
        ("dark_temporal_var_dn2", pa.float64()),
        ("dark_spatial_var_dn2", pa.float64()),
        ("dark_frames", pa.int64()),
        ("signal_dn", pa.float64()),
        ("spatial_var_row_dn2", pa.float64()),
        ("spatial_var_col_dn2", pa.float64()),
        ("spatial_var_pixel_dn2", pa.float64()),
        ("dark_spatial_var_row_dn2", pa.float64()),
        ("dark_spatial_var_col_dn2", pa.float64()),
        ("dark_spatial_var_pixel_dn2", pa.float64()),
        ("mean_diff_dn", pa.float64()),
        ("saturated_fraction", pa.float64()),
        ("saturated", pa.bool_()),
        ("clip_level_dn", pa.float64()),
        ("clip_source", pa.string()),
        ("bayer", pa.string()),
        *CHANNEL_FIELDS,
        *EDGE_FIELDS,
        ("exposure_us_readback", pa.float64()),
        ("gain_db_readback", pa.float64()),
        ("light_on_readback", pa.bool_()),
        ("light_level_readback", pa.float64()),
        ("light_current_a_readback", pa.float64()),
        ("light_measured_current_a", pa.float64()),
        ("lights_readback", pa.string()),
        ("spectrometer_integration_ms_readback", pa.float64()),
        ("spectrometer_averaging_readback", pa.int64()),
        ("readback_t_start_ns", pa.int64()),
        ("readback_t_end_ns", pa.int64()),
        ("attempts", pa.int64()),
        ("temperature_c", pa.float64()),
        ("irradiance_w_m2", pa.float64()),
        ("irradiance_position", pa.string()),
        ("t_start_ns", pa.int64()),
        ("t_end_ns", pa.int64()),
        ("frame_ids", pa.list_(pa.int64())),
    ]
)
CLOCK_COLUMNS = ("readback_t_start_ns", "readback_t_end_ns", "t_start_ns", "t_end_ns")
"""The point columns holding wall-clock times (ns since the epoch): the only ones two runs of one plan with one
seed on the simulated rig may differ in."""
SPECTRA_SCHEMA = pa.schema(
    [
        ("sweep_id", pa.string()),
        ("point_index", pa.int64()),
        ("position", pa.string()),
        ("wavelength_nm", pa.float64()),
        ("irradiance_w_m2_nm", pa.float64()),
    ]
)
REQUIRED_POINT_KEYS = ("sweep_id", "point_index", "kind", "frames")
KEY = ["sweep_id", "point_index"]
TABLES = {"points": POINT_SCHEMA, "spectra": SPECTRA_SCHEMA}
FLOAT_COLUMNS = tuple(f.name for f in POINT_SCHEMA if pa.types.is_floating(f.type))
POINT_COLUMNS = tuple(POINT_SCHEMA.names)  # in order (pyarrow builds a new list at each `.names`)
_KNOWN_COLUMNS = frozenset(POINT_COLUMNS)


def utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


class DatasetLocked(UwlabError):
    """Another live process is writing the dataset (the message names its host and pid)."""


def check_point_row(row: dict) -> dict:
    """A point row with every `POINT_SCHEMA` column (missing ones null) — the one rule of what a recorded point
    is: unknown columns, missing required ones, an unknown kind, fewer than 2 frames, or a NaN/infinite number
    (a measurement that failed is not recorded) raise `ConfigError` naming the column."""
    for key in row:
        if key not in _KNOWN_COLUMNS:
            raise ConfigError(f"point.{key}", row[key], "unknown dataset column")
    for key in REQUIRED_POINT_KEYS:
        if row.get(key) is None:
            raise ConfigError(f"point.{key}", None, "required")
    if row["kind"] not in KINDS:
        raise ConfigError("point.kind", row["kind"], f"must be one of {', '.join(KINDS)}")
    if int(row["frames"]) < 2:
        raise ConfigError("point.frames", row["frames"], "must be >= 2 (temporal variance needs frame pairs)")
    for key in FLOAT_COLUMNS:
        value = row.get(key)
        if value is not None and not (isinstance(value, numbers.Real) and math.isfinite(value)):
            raise ConfigError(f"point.{key}", value, "must be a finite number (null when not applicable)")
    return {name: row.get(name) for name in POINT_COLUMNS}


def point_row(
    *,
    sweep_id: str,
    point_index: int,
    kind: str,
    bright: StackStatistics,
    dark: StackStatistics | None,
    clip: ClipLevel,
    saturation_threshold: float = POINT_SATURATED_FRACTION,
    edges: dict[str | None, EdgeMTF] | None = None,
    **columns: Any,
) -> dict:
    """The dataset row of one measured point — the one place a row is built.

    From the point's bright and dark stacks (`uwlab.experiments.frames.stack`) come ``frames``, ``mean_dn``,
    ``temporal_var_dn2``, ``spatial_var_dn2`` (unfiltered), the row/column/pixel parts of the highpassed spatial
    variance corrected for temporal noise (``spatial_var_{row,col,pixel}_dn2``, EMVA 1288 Release 4.0 eq. 44; null
    for a ROI too small for the highpass), ``mean_diff_dn`` (μ[0] − μ[1] of the first frame pair), the ``dark_*``
    columns and ``signal_dn = mean_dn − dark_mean_dn`` (null without dark frames); from the clip level and the one
    saturation rule (`uwlab.experiments.saturation`) ``saturated_fraction``, ``saturated``, ``clip_level_dn`` and
    ``clip_source``. A raw Bayer point (``bright.channels``, `uwlab.experiments.frames.stack`) has the same per
    colour channel, ``<red|green|blue>_<statistic>`` (`CHANNEL_STATISTICS`: its ``pixels`` per frame, the means,
    variances and ``signal_dn`` = its mean − its dark mean, its saturated fraction at the frame's one clip level and
    the flag by the same threshold, the highpassed split of its sites' planes; EMVA 1288 Release 4.0 Linear §1.2:
    each channel is a sensor of its own); they are null for a monochrome point. ``columns`` are the settings and
    identity columns of `POINT_SCHEMA` (camera, lens, exposure, read-backs, irradiance, times, the Bayer layout
    ``bayer``, ...). A geometry point's ``edges`` (`uwlab.experiments.frames.esfr.measure_edge`: None → the edge of
    the whole image or a mosaic's green, channel name → its own) give ``edge_roi_{x,y,w,h}``, ``mtf50_cy_per_px``,
    ``mtf_nyquist``, ``edge_angle_deg`` and the per-channel ``<channel>_…`` (`EDGE_FIELDS`); a column given twice,
    an unknown column or a missing required one raises `ConfigError` naming it.
    """
    derived = {
        "frames": bright.frames,
        "mean_dn": bright.mean_dn,
        "temporal_var_dn2": bright.temporal_var_dn2,
        "spatial_var_dn2": bright.spatial_var_dn2,
        **_split_columns("", bright),
        "mean_diff_dn": bright.mean_diff_dn,
        "dark_mean_dn": dark.mean_dn if dark else None,
        "dark_temporal_var_dn2": dark.temporal_var_dn2 if dark else None,
        "dark_spatial_var_dn2": dark.spatial_var_dn2 if dark else None,
        **_split_columns("dark_", dark),
        "dark_frames": dark.frames if dark else 0,
        "signal_dn": bright.mean_dn - dark.mean_dn if dark else None,
        "saturated_fraction": bright.saturated_fraction,
        "saturated": point_saturated(bright.saturated_fraction, saturation_threshold),
        "clip_level_dn": clip.dn,
        "clip_source": clip.source,
        **_channel_columns(bright, dark, saturation_threshold),
        **_edge_columns(edges),
    }
    twice = sorted(set(derived) & set(columns))
    if twice:
        raise ConfigError(f"point.{twice[0]}", columns[twice[0]], "derived from the frame statistics; do not pass it")
    return check_point_row({"sweep_id": sweep_id, "point_index": point_index, "kind": kind, **derived, **columns})


def _edge_columns(edges: dict[str | None, EdgeMTF] | None) -> dict:
    """A geometry point's e-SFR columns (`EDGE_FIELDS`), {} for another point."""
    if edges is None:
        return {}
    whole = edges[None]
    x, y, w, h = whole.roi
    columns: dict[str, Any] = {"edge_roi_x": x, "edge_roi_y": y, "edge_roi_w": w, "edge_roi_h": h}
    for channel, edge in edges.items():
        prefix = "" if channel is None else f"{channel}_"
        columns |= {
            f"{prefix}mtf50_cy_per_px": edge.mtf50_cy_per_px,
            f"{prefix}mtf_nyquist": edge.mtf_nyquist,
            f"{prefix}edge_angle_deg": edge.angle_deg,
        }
    return columns


def _channel_columns(bright: StackStatistics, dark: StackStatistics | None, saturation_threshold: float) -> dict:
    """The per-channel columns of a Bayer point (`CHANNEL_STATISTICS`), {} for a monochrome one."""
    if bright.channels is None:
        return {}
    dark_channels = None if dark is None else dark.channels
    if dark is not None and dark_channels is None:
        raise ConfigError("point.dark", "monochrome", "the bright frames are Bayer: dark frames must be too")
    columns: dict[str, Any] = {}
    for colour, channel in CHANNEL_NAMES.items():
        lit = bright.channels[colour]
        unlit = dark_channels[colour] if dark_channels is not None else None
        columns |= {
            f"{channel}_pixels": lit.pixels,
            f"{channel}_mean_dn": lit.mean_dn,
            f"{channel}_temporal_var_dn2": lit.temporal_var_dn2,
            f"{channel}_spatial_var_dn2": lit.spatial_var_dn2,
            f"{channel}_dark_mean_dn": unlit.mean_dn if unlit else None,
            f"{channel}_dark_temporal_var_dn2": unlit.temporal_var_dn2 if unlit else None,
            f"{channel}_dark_spatial_var_dn2": unlit.spatial_var_dn2 if unlit else None,
            f"{channel}_signal_dn": lit.mean_dn - unlit.mean_dn if unlit else None,
            f"{channel}_saturated_fraction": lit.saturated_fraction,
            f"{channel}_saturated": point_saturated(lit.saturated_fraction, saturation_threshold),
            **_split_columns(f"{channel}_", lit),
            **_split_columns(f"{channel}_dark_", unlit),
        }
    return columns


# The whole-ROI columns a channel's own replace in `channel_view`.
CHANNEL_VIEW_COLUMNS = (
    "mean_dn",
    "temporal_var_dn2",
    "spatial_var_dn2",
    "dark_mean_dn",
    "dark_temporal_var_dn2",
    "dark_spatial_var_dn2",
    "signal_dn",
    "saturated_fraction",
    "saturated",
    *(f"{prefix}spatial_var_{part}_dn2" for prefix in ("", "dark_") for part in ("row", "col", "pixel")),
)


def channel_view(points: pd.DataFrame, channel: str) -> pd.DataFrame:
    """The points as one colour ``channel`` ("red", "green", "blue") of their Bayer mosaics saw them: the whole-ROI
    statistics (`CHANNEL_VIEW_COLUMNS`) replaced by the channel's own, ``pixels`` its sites per frame and
    ``channel`` its name (the design model's ``sensor.channel``), so that anything reading a point (the fit's
    forward model, a photon-transfer check) reads the channel as a sensor of its own (EMVA 1288 Release 4.0 Linear
    §1.2). Points without the channel's columns (monochrome, or recorded before they existed) are refused:
    `ConfigError` naming their sweeps.
    """
    if channel not in CHANNEL_NAMES.values():
        raise ConfigError("channel", channel, f"must be one of {', '.join(CHANNEL_NAMES.values())}")
    missing = points[f"{channel}_mean_dn"].isna() if f"{channel}_mean_dn" in points else pd.Series(True, points.index)
    if missing.any():
        sweeps = ", ".join(dict.fromkeys(points.loc[missing, "sweep_id"].astype(str)))
        raise ConfigError("channel", channel, f"sweeps {sweeps} have no per-channel columns (not a Bayer format)")
    view = points.copy()
    for column in CHANNEL_VIEW_COLUMNS:
        view[column] = points[f"{channel}_{column}"]
    return view.assign(pixels=points[f"{channel}_pixels"], channel=channel)


def _split_columns(prefix: str, stats: StackStatistics | None) -> dict:
    spatial = stats.spatial if stats is not None else None
    return {
        f"{prefix}spatial_var_{part}_dn2": getattr(spatial, part) if spatial is not None else None
        for part in ("row", "col", "pixel")
    }


def spectra_frame(sweep_id: str, point_index: int, readings: list[tuple[str, Any, Any]]) -> pd.DataFrame:
    """Long-format spectra rows of one point from ``[(position, wavelength_nm, irradiance_w_m2_nm), ...]``."""
    parts = [
        pd.DataFrame(
            {
                "sweep_id": sweep_id,
                "point_index": int(point_index),
                "position": position,
                "wavelength_nm": pd.Series(wavelength, dtype=float),
                "irradiance_w_m2_nm": pd.Series(irradiance, dtype=float),
            }
        )
        for position, wavelength, irradiance in readings
    ]
    if not parts:
        return pd.DataFrame(columns=SPECTRA_SCHEMA.names)
    return pd.concat(parts, ignore_index=True)


class Dataset:
    """A dataset directory. `open` reads the last committed state (no lock); `create` and `open_for_writing` return
    a writer that holds the dataset's lock until `close` (or process exit) and appends points, each durable on
    return. A writer is a context manager."""

    def __init__(
        self,
        root: Path,
        metadata: dict,
        store: PartStore,
        lock: OwnerLock | None = None,
        metadata_problems: tuple[str, ...] = (),
    ):
        self.root = root
        self.metadata = metadata
        self.metadata_problems = metadata_problems
        self._store = store
        self._lock = lock
        self._keys: set[tuple[str, int]] | None = None

    # -- creation and opening ---------------------------------------------------------------------
    @classmethod
    def create(
        cls,
        root: str | os.PathLike,
        plan: dict,
        *,
        plan_sha256: str,
        devices: dict | None = None,
        rigs: dict | None = None,
        sim: bool = False,
        sim_truth: dict | None = None,
        force: bool = False,
        purpose: str = "creating the dataset",
    ) -> Dataset:
        """A new, empty dataset at ``root``, open for writing. A dataset with recorded points there is refused
        (`ConfigError` on ``out``) unless ``force``, which removes only the dataset's own entries
        (`DATASET_ENTRIES`); one with nothing recorded (a sweep that stopped before its first point) is replaced."""
        root = Path(root)
        if root.exists() and not root.is_dir():
            raise ConfigError("out", str(root), "exists and is not a directory")
        try:
            root.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DatasetWriteError(f"dataset {root}: cannot create the directory ({exc.strerror or exc})") from exc
        lock = _take_lock(root, purpose)
        try:
            existing = [name for name in DATASET_ENTRIES if (root / name).exists()]
            if existing and not force and not _nothing_recorded(root):
                raise ConfigError(
                    "out",
                    str(root),
                    "a dataset with recorded points exists there; use --resume to "
                    "complete it or --force to overwrite it",
                )
            for name in existing:
                _remove(root / name)
            metadata = {
                "plan": plan,
                "plan_sha256": plan_sha256,
                "uwlab_version": __version__,
                "devices": devices or {},
                "rigs": rigs or {},
                "host": socket.gethostname(),
                "started_utc": utc_now(),
                "finished_utc": None,
                "provenance": provenance(),
                "sim": bool(sim),
                "sim_truth": sim_truth or {},
            }
            dataset = cls(root, metadata, _store(root), lock)
            dataset._save_metadata()
        except BaseException:
            lock.release()
            raise
        dataset._keys = set()
        return dataset

    @classmethod
    def open(cls, root: str | os.PathLike) -> Dataset:
        """The dataset at ``root`` for reading (its last committed state)."""
        root = Path(root)
        metadata, problems = read_metadata(root)
        return cls(root, metadata, _load_store(root), metadata_problems=problems)

    @classmethod
    def open_for_writing(cls, root: str | os.PathLike, purpose: str = "writing") -> Dataset:
        """The dataset at ``root`` with its lock held: refused (one line naming the holder's host and pid) while
        another writer holds it; a lock left by a dead process on this host is taken over."""
        root = Path(root)
        read_metadata(root)  # refuse a folder that is not a dataset before creating a lock file in it
        lock = _take_lock(root, purpose)
        try:
            metadata, problems = read_metadata(root)
            return cls(root, metadata, _load_store(root), lock, metadata_problems=problems)
        except BaseException:
            lock.release()
            raise

    @property
    def writable(self) -> bool:
        return self._lock is not None and self._lock.held

    def close(self) -> None:
        """Release the lock (readers: nothing to do)."""
        if self._lock is not None:
            self._lock.release()

    def __enter__(self) -> Dataset:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- writing ----------------------------------------------------------------------------------
    def append_point(self, row: dict, spectra: pd.DataFrame | None = None, frames: FrameRecorder | None = None) -> None:
        """Record one completed point — its row (`check_point_row`), its spectra (long format) and its raw frames
        (`frame_recorder`) — durably before returning. A point already recorded (same sweep_id and point_index)
        is refused: resuming must skip it."""
        self._require_writer()
        row = check_point_row(row)
        key = (row["sweep_id"], int(row["point_index"]))
        if key in self._recorded_keys():
            raise ConfigError("point", f"{key[0]}#{key[1]}", "already recorded in this dataset")
        try:
            tables = {"points": pa.Table.from_pylist([row], schema=POINT_SCHEMA)}
        except (pa.ArrowInvalid, pa.ArrowTypeError) as exc:
            raise ConfigError("point", f"{key[0]}#{key[1]}", f"does not fit the dataset schema ({exc})") from None
        if spectra is not None and len(spectra):
            tables["spectra"] = _spectra_table(spectra, key)
        if frames is not None:
            try:
                frames.commit()
            except OSError as exc:
                raise DatasetWriteError(
                    f"dataset {self.root}: cannot store the frames of {key[0]}#{key[1]} "
                    f"({exc.strerror or exc}); everything recorded before is intact"
                ) from exc
        self._store.append(tables)
        self._recorded_keys().add(key)

    def frame_recorder(self, sweep_id: str, point_index: int) -> FrameRecorder:
        """Somewhere to write a point's raw frames; they become part of the dataset with the point's row
        (``append_point(..., frames=recorder)``)."""
        self._require_writer()
        final = point_folder(self.root, sweep_id, point_index)
        return self._recorder(final.parent, final)

    def dark_block_recorder(self, sweep_id: str) -> FrameRecorder:
        """Somewhere to write a sweep's shared dark frames (``dark = "block"``), for `FrameRecorder.link_darks`;
        discard it when the sweep ends."""
        self._require_writer()
        return self._recorder(self.root / FRAMES_DIR / sweep_folder(sweep_id), None)

    def _recorder(self, sweep_dir: Path, final: Path | None) -> FrameRecorder:
        try:
            return FrameRecorder(sweep_dir, final)
        except OSError as exc:
            raise DatasetWriteError(f"dataset {self.root}: cannot write frames ({exc.strerror or exc})") from exc

    def update_metadata(self, **changes: Any) -> None:
        """Merge top-level keys into metadata.json (atomically); dict values are merged one level deep."""
        self._require_writer()
        for key, value in changes.items():
            current = self.metadata.get(key)
            self.metadata[key] = (
                {**current, **value} if isinstance(current, dict) and isinstance(value, dict) else value
            )
        self._save_metadata()

    def finish(self) -> None:
        self.update_metadata(finished_utc=utc_now())

    def remove_strays(self) -> None:
        """Remove what no committed state names: part files and temporaries of interrupted writes, staging folders
        of frames, frame folders of points not recorded. Call it on a dataset that passes its check (frames of
        points in a damaged part would look unrecorded)."""
        self._require_writer()
        self._store.remove_strays()
        for folder in staging_folders(self.root):
            shutil.rmtree(folder, ignore_errors=True)
        recorded = self.completed()
        for key, folder in stored_point_folders(self.root).items():
            if key not in recorded:
                shutil.rmtree(folder, ignore_errors=True)

    def restore_copies(self) -> None:
        """Rewrite both copies of the metadata and the manifest from what was read (the intact copies)."""
        self._require_writer()
        self._save_metadata()
        self._store.reseal()

    def _save_metadata(self) -> None:
        write_sealed(self.root / METADATA_FILE, json.loads(dumps(self.metadata)), indent=2)
        self.metadata_problems = ()

    def _require_writer(self) -> None:
        if not self.writable:
            raise DatasetWriteError(f"dataset {self.root}: opened for reading; use Dataset.open_for_writing")

    # -- reading ----------------------------------------------------------------------------------
    @property
    def store(self) -> PartStore:
        """The part store (`uwlab.experiments.dataset_store`), for checking and repairing."""
        return self._store

    def points(self) -> pd.DataFrame:
        """Completed points, one row each, in recording order (nullable columns as pandas NA/None)."""
        return self._store.read_all("points").to_pandas()

    def spectra(self) -> pd.DataFrame:
        """Spectra of the recorded points, long format, in recording order."""
        return self._store.read_all("spectra").to_pandas()

    def completed(self) -> frozenset[tuple[str, int]]:
        """``{(sweep_id, point_index)}`` of the recorded points."""
        return frozenset(self._recorded_keys())

    def _recorded_keys(self) -> set[tuple[str, int]]:
        if self._keys is None:
            table = self._store.read_all("points").select(KEY).to_pydict()
            self._keys = set(zip(table["sweep_id"], table["point_index"], strict=True))
        return self._keys

    def frames(self, sweep_id: str, point_index: int) -> PointFrames:
        """The raw frames of a recorded point (plan option ``save_frames``): TIFF paths, bright and dark, in
        acquisition order (`uwlab.experiments.dataset_frames.read_frame` reads one)."""
        if (sweep_id, int(point_index)) not in self.completed():
            raise ConfigError("point", f"{sweep_id}#{point_index}", "not recorded in this dataset")
        found = point_frames(self.root, sweep_id, point_index)
        if not found.bright:
            raise ConfigError(
                "point", f"{sweep_id}#{point_index}", "has no raw frames (its sweep ran without save_frames = true)"
            )
        return found

    @property
    def plan_sha256(self) -> str:
        return self.metadata["plan_sha256"]


def _spectra_table(spectra: pd.DataFrame, key: tuple[str, int]) -> pa.Table:
    """A point's spectra as a table: rows of that point only, finite numbers."""
    table = pa.Table.from_pandas(spectra[SPECTRA_SCHEMA.names], schema=SPECTRA_SCHEMA, preserve_index=False)
    keys = [pc.unique(table[name]).to_pylist() for name in KEY]
    if keys != [[key[0]], [key[1]]]:
        raise ConfigError("spectra", keys, f"rows must belong to the point {key[0]}#{key[1]}")
    for name in ("wavelength_nm", "irradiance_w_m2_nm"):
        if not pc.all(pc.is_finite(table[name])).as_py():
            raise ConfigError(f"spectra.{name}", "NaN or infinite", "must be finite")
    return table


def _store(root: Path) -> PartStore:
    return PartStore(root, TABLES, cached=("points",))


def _load_store(root: Path) -> PartStore:
    try:
        return _store(root).load()
    except ManifestDamaged as exc:
        raise ConfigError("dataset", str(root), f"{exc}; no copy of {MANIFEST_FILE} can be trusted") from None


def read_metadata(root: Path) -> tuple[dict, tuple[str, ...]]:
    """A dataset's ``metadata.json`` from its first trustworthy copy (`uwlab.experiments.dataset_store.read_sealed`)
    and what was wrong with the other copy; `ConfigError` (one line) for a folder that is not a dataset or whose
    metadata no copy holds."""
    root = Path(root)
    try:
        found = read_sealed(root / METADATA_FILE)
    except (FileNotFoundError, NotADirectoryError):
        raise ConfigError("dataset", str(root), f"not a dataset (no {METADATA_FILE})") from None
    except (OSError, ValueError) as exc:
        raise ConfigError("dataset", str(root), f"unreadable {METADATA_FILE} ({exc})") from None
    if "plan_sha256" not in found.document:
        raise ConfigError("dataset", str(root), f"{METADATA_FILE} has no plan_sha256")
    return found.document, found.problems


def _take_lock(root: Path, purpose: str) -> OwnerLock:
    lock = OwnerLock(root / LOCK_FILE, purpose)
    try:
        lock.acquire()
    except LockHeld as exc:
        raise DatasetLocked(f"dataset {exc}") from None
    except OSError as exc:
        raise DatasetWriteError(
            f"dataset {root}: cannot lock it for writing ({exc.strerror or exc}); nothing was changed"
        ) from None
    return lock


def _nothing_recorded(root: Path) -> bool:
    """True when the dataset at ``root`` records no point, no frames and nothing set aside (a sweep that stopped
    before its first point): replacing it loses nothing."""
    try:
        store = _store(root).load()
    except ManifestDamaged:
        return False
    return not store.parts and not stored_point_folders(root) and not (root / QUARANTINE_DIR).exists()


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink()
