"""Raw frames of a dataset's points (plan option ``save_frames``): TIFF files with their settings in the metadata.

Layout (docs/sweeps.md, "Raw frames"): ``frames/<sweep>/<point_index, 5 digits>/bright-<n>.tiff`` and
``dark-<n>.tiff`` (n: 3 digits, acquisition order), each the full image the camera delivered (the analysis ROI is
in the metadata). ``<sweep>`` is the sweep id, percent-encoded where it is not a plain file name (`sweep_folder`).
A sweep's shared dark block (``dark = "block"``) is linked (hard links, else copies) into the folder of every
point that used it, so each point folder holds everything that point was computed from.

Each TIFF's ImageDescription is JSON (tifffile's "shaped" metadata, `read_frame`): ``role`` ("bright" or
"dark"), ``number``, ``frame_id``, ``timestamp_ns``, ``pixel_format``, ``settings`` (the camera's read-back
settings: exposure_us, gain_db, black_level, window, binning, ...) and what the sweep adds (sweep_id,
point_index, light_on, light_level, roi, camera identity, f_number).

Frames are written (each fsync'ed) into a hidden staging folder, renamed into place by `FrameRecorder.commit`
just before the point's row is committed (`uwlab.experiments.dataset.Dataset.append_point`): a recorded point
has all its frames; a folder of a point that is not recorded (a crash between the two) is removed by the next
writer.
"""

from __future__ import annotations

import io
import os
import secrets
import shutil
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote, unquote

import numpy as np

from uwlab.experiments.dataset_store import fsync_directory, write_durable
from uwlab.model.data import MAX_BINARY_BYTES, check_input_file

FRAMES_DIR = "frames"
ROLES = ("bright", "dark")


@dataclass(frozen=True)
class PointFrames:
    """The raw frames of one recorded point: TIFF paths in acquisition order (``dark`` empty without dark frames)."""

    bright: tuple[Path, ...]
    dark: tuple[Path, ...]


def sweep_folder(sweep_id: str) -> str:
    """The folder name of a sweep's frames: its id, percent-encoded where it is not a plain file name.

    >>> sweep_folder("imx250-30mm"), sweep_folder("a/b"), sweep_folder("..")
    ('imx250-30mm', 'a%2Fb', '%2E.')
    """
    name = quote(sweep_id, safe="")
    return "%2E" + name[1:] if name.startswith(".") else name


def point_folder(root: Path, sweep_id: str, point_index: int) -> Path:
    return Path(root) / FRAMES_DIR / sweep_folder(sweep_id) / f"{int(point_index):05d}"


def point_frames(root: Path, sweep_id: str, point_index: int) -> PointFrames:
    """The frames stored for a point (empty tuples when none were saved)."""
    folder = point_folder(root, sweep_id, point_index)
    listed = sorted(folder.glob("*.tiff")) if folder.is_dir() else []
    return PointFrames(*(tuple(p for p in listed if p.name.startswith(f"{role}-")) for role in ROLES))


def stored_point_folders(root: Path) -> dict[tuple[str, int], Path]:
    """``{(sweep_id, point_index): folder}`` of every committed point folder."""
    found = {}
    for sweep_dir in sorted((Path(root) / FRAMES_DIR).glob("*")):
        if sweep_dir.is_dir() and not sweep_dir.name.startswith("."):
            for folder in sweep_dir.iterdir():
                if folder.is_dir() and folder.name.isdigit():
                    found[(unquote(sweep_dir.name), int(folder.name))] = folder
    return found


def staging_folders(root: Path) -> list[Path]:
    """Hidden folders of frames being written (left behind by a crash when their writer is gone)."""
    return sorted(p for p in (Path(root) / FRAMES_DIR).glob("*/.*") if p.is_dir())


def read_frame(path: str | os.PathLike) -> tuple[np.ndarray, dict]:
    """(image, metadata) of a stored frame."""
    import tifffile

    with tifffile.TiffFile(check_input_file(path, "frame", MAX_BINARY_BYTES, "TIFF")) as tif:
        metadata = dict(tif.shaped_metadata[0]) if tif.shaped_metadata else {}
        metadata.pop("shape", None)
        return tif.asarray(), metadata


class FrameRecorder:
    """Frames being written for one point (``final``: its folder) or for a sweep's dark block (``final`` None:
    linked into the points that use it, then discarded)."""

    def __init__(self, sweep_dir: Path, final: Path | None):
        self.final = final
        tag = final.name if final is not None else "dark-block"
        self.staging = sweep_dir / f".{tag}.{os.getpid()}-{secrets.token_hex(4)}"
        self.staging.mkdir(parents=True)
        self.counts = dict.fromkeys(ROLES, 0)

    def add(self, role: str, image: np.ndarray, metadata: dict) -> Path:
        """Write the next frame of ``role`` with ``metadata`` (JSON-able) in its TIFF description."""
        import tifffile

        number = self.counts[role]
        buffer = io.BytesIO()
        tifffile.imwrite(buffer, image, metadata={"role": role, "number": number, **metadata})
        path = self.staging / f"{role}-{number:03d}.tiff"
        write_durable(path, buffer.getvalue())
        self.counts[role] = number + 1
        return path

    def forget(self, role: str) -> None:
        """Drop the frames of ``role`` written so far (a measurement attempt that will not be recorded)."""
        for path in self.staging.glob(f"{role}-*.tiff"):
            path.unlink()
        self.counts[role] = 0

    def link_darks(self, block: FrameRecorder) -> None:
        """Give this point the dark frames of a sweep's dark block (hard links, else copies)."""
        for source in sorted(block.staging.glob("dark-*.tiff")):
            target = self.staging / source.name
            try:
                os.link(source, target)
            except OSError:
                write_durable(target, source.read_bytes())
            self.counts["dark"] += 1

    def commit(self) -> None:
        """Rename the staging folder into place (replacing a folder left by an unrecorded attempt), durably."""
        if self.final is None:
            raise ValueError("a sweep's dark block is linked into its points (link_darks), not committed")
        fsync_directory(self.staging)
        if self.final.exists():
            shutil.rmtree(self.final)
        os.rename(self.staging, self.final)
        fsync_directory(self.final.parent)

    def discard(self) -> None:
        shutil.rmtree(self.staging, ignore_errors=True)
