"""Export of a dataset's photon transfer as an EMVA 1288 descriptor dataset (`uwlab.experiments.emva.descriptor`
format).

With recorded frames (the plan option ``save_frames = true``; `uwlab.experiments.dataset.Dataset.frames` finds a
point's bright and dark frames) the images are the camera's, cropped to the analysis ROI: the first two bright and
two dark frames of every point, the dark frames of the camera's dark sweeps at other exposures, and — when the
point nearest 50 % of saturation has more than two frames of each kind — all of them as the nonuniformity stacks.
Without recorded frames the images are synthetic: generated from each point's statistics (mean, temporal variance
with quantisation, and the highpassed spatial variance split into a dark and a photo-response fixed pattern shared by
all images), at a chosen size; the descriptor's comments say so.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError
from uwlab.experiments.emva.descriptor import DESCRIPTOR_NAME, Block, Descriptor, format_descriptor
from uwlab.experiments.emva.transfer import PhotonTransfer, half_saturation_index, saturation
from uwlab.outputs import output_dir

SPATIAL_FRAMES = 16


@dataclass(frozen=True)
class Pattern:
    """Fixed-pattern maps shared by all synthetic images of one export (dark and photo-response parts)."""

    dark: np.ndarray
    photo: np.ndarray


def synthetic_frames(
    mean_dn: float,
    temporal_var_dn2: float,
    spatial_var_dn2: float,
    dark_spatial_var_dn2: float,
    count: int,
    pattern: Pattern,
    rng: np.random.Generator,
    bits: int,
) -> Iterator[np.ndarray]:
    """Frames whose mean, temporal variance (quantisation included) and spatial variance (split into the dark part
    and the photo-response part) reproduce the given statistics."""
    dark_sd = np.sqrt(max(dark_spatial_var_dn2, 0.0))
    photo_sd = np.sqrt(max(spatial_var_dn2 - max(dark_spatial_var_dn2, 0.0), 0.0))
    fixed = mean_dn + dark_sd * pattern.dark + photo_sd * pattern.photo
    noise_sd = np.sqrt(max(temporal_var_dn2 - 1.0 / 12.0, 0.0))
    dtype = np.uint8 if bits <= 8 else np.uint16
    for _ in range(count):
        frame = np.rint(fixed + noise_sd * rng.standard_normal(fixed.shape))
        yield np.clip(frame, 0, (1 << bits) - 1).astype(dtype)


def _finite(value: float) -> float:
    return float(value) if np.isfinite(value) else 0.0


def write_descriptor(
    pt: PhotonTransfer, out_dir: str | Path, *, shape: tuple[int, int] = (256, 256), seed: int = 0, source: str = ""
) -> Path:
    """Export a photon transfer as a descriptor dataset with synthetic TIFF images (see `synthetic_frames`): two
    bright and two dark images per point, plus nonuniformity stacks (`SPATIAL_FRAMES` images) at the point nearest
    50 % saturation. Refuses to write into an existing descriptor."""
    import tifffile

    target = _target(out_dir)
    out = target.parent
    pt = pt.sorted()
    rng = np.random.default_rng(seed)
    pattern = Pattern(rng.standard_normal(shape), rng.standard_normal(shape))
    blocks: list[Block] = []
    counter = iter(range(10**9))

    def emit(dark: bool, exposure_s: float, photons: float, frames) -> None:
        names = []
        for frame in frames:
            name = f"images/image{next(counter):05d}.tif"
            tifffile.imwrite(out / name, frame)
            names.append(name)
        blocks.append(Block(dark, exposure_s * 1e9, photons, tuple(names)))

    def frames_of(i: int, dark: bool, count: int):
        s2_dark = _finite(pt.dark_spatial.total[i])
        if dark:
            return synthetic_frames(
                pt.dark_mean_dn[i], pt.dark_temporal_var_dn2[i], s2_dark, s2_dark, count, pattern, rng, pt.bit_depth
            )
        return synthetic_frames(
            pt.mean_dn[i],
            pt.temporal_var_dn2[i],
            _finite(pt.spatial.total[i]),
            s2_dark,
            count,
            pattern,
            rng,
            pt.bit_depth,
        )

    dark_done = set()
    for i in range(len(pt.photons)):
        emit(False, pt.exposure_s[i], pt.photons[i], frames_of(i, False, 2))
        key = round(pt.exposure_s[i] * 1e9, 3)
        if key not in dark_done:
            dark_done.add(key)
            emit(True, pt.exposure_s[i], 0.0, frames_of(i, True, 2))
    i = half_saturation_index(pt, saturation(pt).index)
    emit(False, pt.exposure_s[i], pt.photons[i], frames_of(i, False, SPATIAL_FRAMES))
    emit(True, pt.exposure_s[i], 0.0, frames_of(i, True, SPATIAL_FRAMES))
    comments = (
        f"EMVA 1288 descriptor written by uwlab from {source or pt.source}",
        "Images are SYNTHETIC: raw frames were not saved, so each image set is generated from the recorded",
        "per-point statistics (mean, temporal variance, highpassed spatial variance);",
        f"pixel values are not the camera's. Image size {shape[1]} x {shape[0]} px (not the ROI size).",
        "b exposure_ns photons_per_pixel / d exposure_ns / i image path (Release 4.0)",
    )
    desc = Descriptor("4.0", pt.bit_depth, shape[1], shape[0], tuple(blocks))
    target.write_text(format_descriptor(desc, comments))
    return target


def has_recorded_frames(dataset, pt: PhotonTransfer) -> bool:
    """Whether the photon transfer's first point kept its raw frames (then every point must have them)."""
    assert pt.point_index is not None  # PhotonTransfer.__post_init__ replaced a None by NaN
    try:
        dataset.frames(pt.sweep_id, int(pt.point_index[0]))
    except ConfigError:
        return False
    return True


def _target(out_dir: str | Path) -> Path:
    """The descriptor's path in ``out_dir`` (`uwlab.outputs.output_dir`: no missing parents created), refusing an
    existing one; the directory and its ``images/`` are created."""
    out = output_dir(out_dir, "--out")
    target = out / DESCRIPTOR_NAME
    if target.exists():
        raise ConfigError("--out", str(target), "exists; refusing to overwrite")
    out.mkdir(exist_ok=True)
    (out / "images").mkdir(exist_ok=True)
    return target


def write_descriptor_from_frames(
    dataset, pt: PhotonTransfer, out_dir: str | Path, *, dark_points=(), source: str = ""
) -> Path:
    """Export the recorded frames of ``pt``'s points (and of ``dark_points``: (sweep_id, point_index, exposure [s])
    of dark sweeps) as a descriptor dataset (module docstring). Refuses to write into an existing descriptor."""
    import tifffile

    from uwlab.experiments.dataset_frames import read_frame

    target = _target(out_dir)
    out = target.parent
    pt = pt.sorted()
    point_index = pt.point_index
    assert point_index is not None  # PhotonTransfer.__post_init__ replaced a None by NaN
    blocks: list[Block] = []
    shape: tuple[int, ...] | None = None
    counter = iter(range(10**9))

    def copy(paths, dark: bool, exposure_s: float, photons: float) -> None:
        nonlocal shape
        names = []
        for path in paths:
            image, metadata = read_frame(path)
            x, y, w, h = metadata.get("roi") or (0, 0, image.shape[1], image.shape[0])
            image = image[y : y + h, x : x + w]
            if shape is None:
                shape = image.shape
            elif image.shape != shape:
                raise ConfigError("frame", str(path), f"ROI {image.shape} differs from the first frame's {shape}")
            name = f"images/image{next(counter):05d}.tif"
            tifffile.imwrite(out / name, image)
            names.append(name)
        blocks.append(Block(dark, exposure_s * 1e9, photons, tuple(names)))

    frames = [dataset.frames(pt.sweep_id, int(i)) for i in point_index]
    dark_exposures = set()
    for i, found in enumerate(frames):
        if len(found.bright) < 2 or len(found.dark) < 2:
            raise ConfigError(
                "point", f"{pt.sweep_id}#{int(point_index[i])}", "needs two recorded bright and two dark frames"
            )
        copy(found.bright[:2], False, pt.exposure_s[i], pt.photons[i])
        key = round(pt.exposure_s[i] * 1e9, 3)
        if key not in dark_exposures:
            dark_exposures.add(key)
            copy(found.dark[:2], True, pt.exposure_s[i], 0.0)
    for sweep_id, point_index, exposure_s in dark_points:
        key = round(exposure_s * 1e9, 3)
        if key not in dark_exposures:
            found = dataset.frames(sweep_id, int(point_index))
            if len(found.bright) >= 2:
                dark_exposures.add(key)
                copy(found.bright[:2], True, exposure_s, 0.0)
    i = half_saturation_index(pt, saturation(pt).index)
    stacks = len(frames[i].bright) > 2 and len(frames[i].dark) > 2
    if stacks:
        copy(frames[i].bright, False, pt.exposure_s[i], pt.photons[i])
        copy(frames[i].dark, True, pt.exposure_s[i], 0.0)
    stack_text = "the frames of the point nearest 50 % of saturation" if stacks else "none (2 frames per point)"
    comments = (
        f"EMVA 1288 descriptor written by uwlab from {source or pt.source}",
        f"Images: the camera's recorded frames (save_frames), cropped to the analysis ROI; stacks: {stack_text}.",
        "b exposure_ns photons_per_pixel / d exposure_ns / i image path (Release 4.0)",
    )
    assert shape is not None  # every point has at least two frames, refused above otherwise
    desc = Descriptor("4.0", pt.bit_depth, shape[1], shape[0], tuple(blocks))
    target.write_text(format_descriptor(desc, comments))
    return target
