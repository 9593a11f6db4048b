"""EMVA 1288 descriptor-file datasets (the interchange format of the EMVA 1288 reference implementation,
github.com/EMVA1288/emva1288, ``doc/datasets/datasets_image.rst`` and ``process/parser.py``; format read,
no code taken).

A plain-text descriptor next to the images; blank lines and lines starting with ``#`` are ignored:

* ``v 4.0`` — the EMVA 1288 release the data were taken for;
* ``n BITS WIDTH HEIGHT`` — once per file (a fifth field, an offset, is tolerated on reading);
* ``b EXPOSURE_NS PHOTONS`` — a bright measurement: exposure [ns], mean photons per pixel μ_p; followed by
  its images;
* ``d EXPOSURE_NS`` — a dark measurement at that exposure, followed by its images;
* ``i RELATIVE/PATH`` — one image of the preceding ``b``/``d`` block (``\\`` accepted as separator); at
  least two per block. Two images make a *temporal* measurement (photon-transfer point), more make a
  *spatial* one (DSNU/PRNU stack);
* ``l NAME VALUE`` — report (LaTeX template) variables.

Every exposure of the temporal series needs its dark block (the reference loader requires it too). Images
are read one at a time (TIFF by tifffile, PNG/PGM and others by OpenCV) into `emva_stream` statistics.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path, PureWindowsPath

import numpy as np

from uwlab.errors import ConfigError
from uwlab.experiments.emva.analysis import QUANTISATION_VAR_DN2, PhotonTransfer, SpatialPoint, half_saturation_index
from uwlab.experiments.emva.stream import StackStatistics, stack_statistics
from uwlab.outputs import output_dir

DESCRIPTOR_NAME = "EMVA1288descriptor.txt"
SPATIAL_FRAMES = 16


@dataclass(frozen=True)
class Block:
    """One ``b``/``d`` block: exposure [ns], photons per pixel (0 for dark) and its image paths."""

    dark: bool
    exposure_ns: float
    photons: float
    images: tuple[str, ...]

    @property
    def spatial(self) -> bool:
        return len(self.images) > 2


@dataclass(frozen=True)
class Descriptor:
    version: str
    bits: int
    width: int
    height: int
    blocks: tuple[Block, ...]
    variables: dict = field(default_factory=dict)


def _number(text: str, path: Path, lineno: int) -> float:
    try:
        return float(text.replace(",", "."))
    except ValueError:
        raise ConfigError(f"{path.name}:{lineno}", text, "not a number") from None


def parse_descriptor(path: str | Path) -> Descriptor:
    """Parse a descriptor file; `ConfigError` names the file and line of any malformed entry."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError("--descriptor", str(path), f"unreadable ({exc})") from None
    version, fmt, blocks, variables = None, None, [], {}
    current: list | None = None
    for lineno, raw in enumerate(lines, 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        tag, *rest = line.split(maxsplit=1 if line.startswith(("i ", "l ")) else -1)
        where = f"{path.name}:{lineno}"
        if tag == "i" and rest and current is not None:
            current[3].append(rest[0].strip())
            continue
        if current is not None:
            blocks.append(_close(current, where))
            current = None
        if tag == "v" and len(rest) == 1:
            version = rest[0]
        elif tag == "n" and len(rest) in (3, 4):
            if fmt is not None:
                raise ConfigError(where, line, "only one 'n bits width height' line is allowed")
            fmt = tuple(int(_number(x, path, lineno)) for x in rest[:3])
        elif tag == "b" and len(rest) == 2:
            current = [False, _number(rest[0], path, lineno), _number(rest[1], path, lineno), []]
        elif tag == "d" and len(rest) == 1:
            current = [True, _number(rest[0], path, lineno), 0.0, []]
        elif tag == "l" and rest:
            name, _, value = rest[0].partition(" ")
            variables[name] = value.strip()
        else:
            raise ConfigError(where, line, "expected 'v', 'n', 'b', 'd', 'i' or 'l' with its fields")
    if current is not None:
        blocks.append(_close(current, f"{path.name}:end"))
    if fmt is None:
        raise ConfigError(f"{path.name}", "n", "missing 'n bits width height' line")
    return Descriptor(version or "", fmt[0], fmt[1], fmt[2], tuple(blocks), variables)


def _close(current: list, where: str) -> Block:
    dark, exposure, photons, images = current
    if len(images) < 2:
        raise ConfigError(where, len(images), "each b/d block needs at least two 'i' image lines")
    return Block(dark, exposure, photons, tuple(images))


def format_descriptor(desc: Descriptor, comments: tuple[str, ...] = ()) -> str:
    """The descriptor text (numbers written with 9 significant digits: parse ∘ format is exact to that)."""
    out = [f"# {c}" for c in comments]
    out += [f"v {desc.version}", "# n bits width height", f"n {desc.bits} {desc.width} {desc.height}"]
    out += [f"l {name} {value}" for name, value in desc.variables.items()]
    for block in desc.blocks:
        out.append(f"d {block.exposure_ns:.9g}" if block.dark else f"b {block.exposure_ns:.9g} {block.photons:.9g}")
        out += [f"i {name}" for name in block.images]
    return "\n".join(out) + "\n"


def read_image(path: Path) -> np.ndarray:
    """One image as a 2-D integer array (TIFF via tifffile, other formats via OpenCV, unchanged depth)."""
    if not path.is_file():
        raise ConfigError("image", str(path), "file not found")
    if path.suffix.lower() in (".tif", ".tiff"):
        import tifffile
        image = tifffile.imread(path)
    else:
        import cv2
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise ConfigError("image", str(path), "unreadable image")
    if image.ndim != 2:
        raise ConfigError("image", str(path), f"expected a monochrome image, got shape {image.shape}")
    return image


def _image_path(base: Path, name: str) -> Path:
    return base.joinpath(*PureWindowsPath(name).parts)


def _block_stats(base: Path, block: Block, full: int) -> StackStatistics:
    return stack_statistics((read_image(_image_path(base, n)) for n in block.images), full)


def photon_transfer_from_descriptor(path: str | Path, pixel_size_um: float | None = None) -> PhotonTransfer:
    """The `PhotonTransfer` of a descriptor dataset (statistics streamed from its images)."""
    path = Path(path)
    desc = parse_descriptor(path)
    base, full = path.parent, (1 << desc.bits) - 1
    temporal = [b for b in desc.blocks if not b.spatial]
    darks = {b.exposure_ns: _block_stats(base, b, full) for b in temporal if b.dark}
    bright = [b for b in temporal if not b.dark]
    if not bright:
        raise ConfigError(path.name, "b", "no bright (b) blocks with two images")
    missing = sorted({b.exposure_ns for b in bright} - set(darks))
    if missing:
        raise ConfigError(path.name, f"d {missing[0]:g}", "no dark images at this exposure")
    stats = [_block_stats(base, b, full) for b in bright]
    dark_at = [darks[b.exposure_ns] for b in bright]
    arr = lambda seq, name: np.array([getattr(s, name) for s in seq], float)  # noqa: E731
    dark_t = np.array(sorted(darks)) * 1e-9
    return PhotonTransfer(
        photons=np.array([b.photons for b in bright]), exposure_s=np.array([b.exposure_ns for b in bright]) * 1e-9,
        mean_dn=arr(stats, "mean_dn"), temporal_var_dn2=arr(stats, "temporal_var_dn2"),
        spatial_var_dn2=arr(stats, "spatial_var_dn2"), frames=arr(stats, "frames"),
        dark_mean_dn=arr(dark_at, "mean_dn"), dark_temporal_var_dn2=arr(dark_at, "temporal_var_dn2"),
        dark_spatial_var_dn2=arr(dark_at, "spatial_var_dn2"), dark_frames=arr(dark_at, "frames"),
        dark_exposure_s=dark_t, dark_series_mean_dn=np.array([darks[t].mean_dn for t in sorted(darks)]),
        dark_series_var_dn2=np.array([darks[t].temporal_var_dn2 for t in sorted(darks)]),
        bit_depth=desc.bits, width_px=desc.width, height_px=desc.height,
        pixel_area_m2=(pixel_size_um * 1e-6) ** 2 if pixel_size_um else None,
        source=f"descriptor {path}", spatial=_spatial_from_descriptor(desc, base, full),
    )


def _spatial_from_descriptor(desc: Descriptor, base: Path, full: int) -> SpatialPoint | None:
    bright = [b for b in desc.blocks if b.spatial and not b.dark]
    dark = [b for b in desc.blocks if b.spatial and b.dark]
    if not bright or not dark:
        return None
    s, d = _block_stats(base, bright[0], full), _block_stats(base, dark[0], full)
    return SpatialPoint(s.mean_dn, s.temporal_var_dn2, s.spatial_var_dn2, s.frames,
                        d.mean_dn, d.temporal_var_dn2, d.spatial_var_dn2, d.frames)


@dataclass(frozen=True)
class _Pattern:
    """Fixed-pattern maps shared by all synthetic images of one export (dark and photo-response parts)."""

    dark: np.ndarray
    photo: np.ndarray


def synthetic_frames(mean_dn: float, temporal_var_dn2: float, spatial_var_dn2: float, dark_spatial_var_dn2: float,
                     count: int, pattern: _Pattern, rng: np.random.Generator, bits: int) -> Iterator[np.ndarray]:
    """Frames whose mean, temporal variance (quantisation included) and temporal-noise-corrected spatial
    variance (split into the dark part and the photo-response part) reproduce the given statistics."""
    dark_sd = np.sqrt(max(dark_spatial_var_dn2, 0.0))
    photo_sd = np.sqrt(max(spatial_var_dn2 - max(dark_spatial_var_dn2, 0.0), 0.0))
    fixed = mean_dn + dark_sd * pattern.dark + photo_sd * pattern.photo
    noise_sd = np.sqrt(max(temporal_var_dn2 - QUANTISATION_VAR_DN2, 0.0))
    dtype = np.uint8 if bits <= 8 else np.uint16
    for _ in range(count):
        frame = np.rint(fixed + noise_sd * rng.standard_normal(fixed.shape))
        yield np.clip(frame, 0, (1 << bits) - 1).astype(dtype)


def _corrected(spatial_var: float, temporal_var: float, frames: float) -> float:
    return float(spatial_var - temporal_var / frames) if np.isfinite(spatial_var) and frames > 0 else 0.0


def write_descriptor(pt: PhotonTransfer, out_dir: str | Path, *, shape: tuple[int, int] = (256, 256),
                     seed: int = 0, source: str = "") -> Path:
    """Export a photon transfer as a descriptor dataset with synthetic TIFF images (see `synthetic_frames`):
    two bright and two dark images per point, plus a spatial stack (`SPATIAL_FRAMES` images) at the point
    nearest 50 % saturation. Refuses to write into an existing descriptor."""
    import tifffile

    out = output_dir(out_dir, "--out")
    target = out / DESCRIPTOR_NAME
    if target.exists():
        raise ConfigError("--out", str(target), "exists; refusing to overwrite")
    out.mkdir(exist_ok=True)
    (out / "images").mkdir(exist_ok=True)
    pt = pt.sorted()
    rng = np.random.default_rng(seed)
    pattern = _Pattern(rng.standard_normal(shape), rng.standard_normal(shape))
    blocks: list[Block] = []
    counter = iter(range(10**9))

    def emit(dark: bool, exposure_s: float, photons: float, frames) -> None:
        names = []
        for frame in frames:
            name = f"images/image{next(counter):05d}.tif"
            tifffile.imwrite(out / name, frame)
            names.append(name)
        blocks.append(Block(dark, exposure_s * 1e9, photons, tuple(names)))

    dark_done = set()
    for i in range(len(pt.photons)):
        s2 = _corrected(pt.spatial_var_dn2[i], pt.temporal_var_dn2[i], pt.frames[i])
        s2d = _corrected(pt.dark_spatial_var_dn2[i], pt.dark_temporal_var_dn2[i], pt.dark_frames[i])
        emit(False, pt.exposure_s[i], pt.photons[i],
             synthetic_frames(pt.mean_dn[i], pt.temporal_var_dn2[i], s2, s2d, 2, pattern, rng, pt.bit_depth))
        if round(pt.exposure_s[i] * 1e9, 3) not in dark_done:
            dark_done.add(round(pt.exposure_s[i] * 1e9, 3))
            emit(True, pt.exposure_s[i], 0.0,
                 synthetic_frames(pt.dark_mean_dn[i], pt.dark_temporal_var_dn2[i], s2d, s2d, 2, pattern, rng,
                                  pt.bit_depth))
    i = half_saturation_index(pt)
    s2d = _corrected(pt.dark_spatial_var_dn2[i], pt.dark_temporal_var_dn2[i], pt.dark_frames[i])
    s2 = _corrected(pt.spatial_var_dn2[i], pt.temporal_var_dn2[i], pt.frames[i])
    emit(False, pt.exposure_s[i], pt.photons[i], synthetic_frames(
        pt.mean_dn[i], pt.temporal_var_dn2[i], s2, s2d, SPATIAL_FRAMES, pattern, rng, pt.bit_depth))
    emit(True, pt.exposure_s[i], 0.0, synthetic_frames(
        pt.dark_mean_dn[i], pt.dark_temporal_var_dn2[i], s2d, s2d, SPATIAL_FRAMES, pattern, rng, pt.bit_depth))
    comments = (
        f"EMVA 1288 descriptor written by uwlab from {source or pt.source}",
        "Images are SYNTHETIC: raw frames were not saved, so each image set is generated from the recorded",
        "per-point statistics (mean, temporal variance, temporal-noise-corrected spatial variance);",
        f"pixel values are not the camera's. Image size {shape[1]} x {shape[0]} px (not the ROI size).",
        "b exposure_ns photons_per_pixel / d exposure_ns / i image path (Release 4.0 linear)",
    )
    desc = Descriptor("4.0", pt.bit_depth, shape[1], shape[0], tuple(blocks))
    target.write_text(format_descriptor(desc, comments))
    return target
