"""EMVA 1288 descriptor-file datasets (the interchange format of the EMVA 1288 reference implementation,
github.com/EMVA1288/emva1288, ``doc/datasets/datasets_image.rst`` and ``process/parser.py``; format read,
no code taken).

A plain-text descriptor next to the images; blank lines and lines starting with ``#`` are ignored:

* ``v 4.0`` — the EMVA 1288 release the data were taken for;
* ``n BITS WIDTH HEIGHT`` — once per file (a fifth field, an offset, is tolerated on reading); BITS one of
  `SUPPORTED_BITS`, WIDTH and HEIGHT positive integers;
* ``b EXPOSURE_NS PHOTONS`` — a bright measurement: exposure [ns] > 0, mean photons per pixel μ_p > 0; followed by
  its images;
* ``d EXPOSURE_NS`` — a dark measurement at that exposure, followed by its images;
* ``i RELATIVE/PATH`` — one image of the preceding ``b``/``d`` block (``\\`` accepted as separator). Two images make
  a *temporal* measurement (a photon-transfer point or a dark-series point), more make a *spatial* one (the
  nonuniformity stacks of Release 4.0 §8: one bright block near 50 % of saturation and one dark block at the same
  exposure);
* ``l NAME VALUE`` — report (LaTeX template) variables.

What is refused, each with one line naming the file and line: a malformed or non-finite number, a non-positive
exposure or photon count, an unsupported bit depth, a block with fewer than two images, a second temporal dark
block at one exposure, bright blocks that neither vary the exposure (one per exposure, Release 4.0 §6.3 method I)
nor the irradiance at one exposure (methods II/III), two bright blocks with the same exposure and photon count, a
bright exposure without its dark block, more than one spatial block of a kind, a spatial block without its partner
at the same exposure; and on reading, an image of the wrong size or type, or with values outside 0 … 2^BITS − 1.

Images are read one at a time (tifffile for TIFFs, OpenCV for other formats and TIFFs tifffile cannot decode; a TIFF
laid out byte for byte as the first one tifffile read, apart from its pixels, is read at its pixels directly,
`_TiffLayout`) into `uwlab.experiments.frames.stack` statistics, one accumulator per block, the blocks spread over
the CPU's threads.
The clip level (`uwlab.experiments.saturation.clip_level`) is found once, from the first image of the brightest
bright block (a pile-up at the top code), else it is the ADC maximum 2^BITS − 1.
"""

from __future__ import annotations

import math
import os
import sys
import threading
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path, PureWindowsPath

import numpy as np

from uwlab.errors import ConfigError
from uwlab.experiments.emva.dark import DarkSeries
from uwlab.experiments.emva.transfer import SheetInfo
from uwlab.experiments.frames.stack import StackAccumulator, StackStatistics, WorkImages
from uwlab.experiments.emva.transfer import NonuniformityStack, PhotonTransfer, SpatialSplit
from uwlab.experiments.saturation import ClipLevel, clip_level
from uwlab.model.data import MAX_BINARY_BYTES, check_input_file, read_text

DESCRIPTOR_NAME = "EMVA1288descriptor.txt"
SUPPORTED_BITS = (8, 10, 12, 14, 16)
MAX_SIZE_PX = 1 << 16
MAX_DESCRIPTOR_BYTES = 10_000_000  # a descriptor names its images: 10 MB is ~100 000 frames
WORKERS = os.cpu_count() or 1


@dataclass(frozen=True)
class Block:
    """One ``b``/``d`` block: exposure [ns], photons per pixel (0 for dark), its image paths and the line it
    starts on."""

    dark: bool
    exposure_ns: float
    photons: float
    images: tuple[str, ...]
    line: int = field(default=0, compare=False)

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


def _parse_number(text: str, where: str, what: str, positive: bool = True) -> float:
    try:
        value = float(text.replace(",", "."))
    except ValueError:
        raise ConfigError(where, text, f"{what}: not a number") from None
    if not math.isfinite(value):
        raise ConfigError(where, text, f"{what}: not a finite number")
    if positive and not value > 0:
        raise ConfigError(where, text, f"{what}: must be > 0")
    return value


def _integer(text: str, where: str, what: str, allowed: tuple[int, ...] | None = None) -> int:
    value = _parse_number(text, where, what)
    if value != int(value) or not 0 < value < MAX_SIZE_PX:
        raise ConfigError(where, text, f"{what}: must be a positive integer below {MAX_SIZE_PX}")
    if allowed is not None and int(value) not in allowed:
        raise ConfigError(where, text, f"{what}: must be one of {', '.join(map(str, allowed))}")
    return int(value)


def parse_descriptor(path: str | Path) -> Descriptor:
    """Parse and check a descriptor file; `ConfigError` names the file and line of any problem (module
    docstring)."""
    path = Path(path)
    lines = read_text(path, "--descriptor", MAX_DESCRIPTOR_BYTES, "descriptor").splitlines()
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
            blocks.append(_close(current, path.name))
            current = None
        if tag == "v" and len(rest) == 1:
            version = rest[0]
        elif tag == "n" and len(rest) in (3, 4):
            if fmt is not None:
                raise ConfigError(where, line, "only one 'n bits width height' line is allowed")
            fmt = (
                _integer(rest[0], where, "bits", SUPPORTED_BITS),
                _integer(rest[1], where, "width"),
                _integer(rest[2], where, "height"),
            )
            if len(rest) == 4:
                _parse_number(rest[3], where, "offset", positive=False)
        elif tag == "b" and len(rest) == 2:
            current = [
                False,
                _parse_number(rest[0], where, "exposure [ns]"),
                _parse_number(rest[1], where, "photons"),
                [],
                lineno,
            ]
        elif tag == "d" and len(rest) == 1:
            current = [True, _parse_number(rest[0], where, "exposure [ns]"), 0.0, [], lineno]
        elif tag == "l" and rest:
            name, _, value = rest[0].partition(" ")
            variables[name] = value.strip()
        else:
            raise ConfigError(where, line, "expected 'v', 'n', 'b', 'd', 'i' or 'l' with its fields")
    if current is not None:
        blocks.append(_close(current, path.name))
    if fmt is None:
        raise ConfigError(f"{path.name}", "n", "missing 'n bits width height' line")
    _check_blocks(blocks, path.name)
    return Descriptor(version or "", fmt[0], fmt[1], fmt[2], tuple(blocks), variables)


def _close(current: list, name: str) -> Block:
    dark, exposure, photons, images, lineno = current
    if len(images) < 2:
        raise ConfigError(f"{name}:{lineno}", len(images), "each b/d block needs at least two 'i' image lines")
    return Block(dark, exposure, photons, tuple(images), lineno)


def _check_blocks(blocks: list[Block], name: str) -> None:
    """The cross-block rules of the module docstring."""
    temporal = [b for b in blocks if not b.spatial]
    seen_dark: dict[float, Block] = {}
    for block in (b for b in temporal if b.dark):
        if block.exposure_ns in seen_dark:
            first = seen_dark[block.exposure_ns].line
            raise ConfigError(
                f"{name}:{block.line}",
                f"d {block.exposure_ns:g}",
                f"a second dark block at this exposure (first at line {first})",
            )
        seen_dark[block.exposure_ns] = block
    bright = [b for b in temporal if not b.dark]
    exposures = {b.exposure_ns for b in bright}
    seen_bright: dict[tuple[float, float], Block] = {}
    by_exposure: dict[float, Block] = {}
    for block in bright:
        where = f"{name}:{block.line}"
        key = (block.exposure_ns, block.photons)
        if key in seen_bright:
            raise ConfigError(
                where,
                f"b {block.exposure_ns:g} {block.photons:g}",
                f"the same bright measurement again (first at line {seen_bright[key].line})",
            )
        seen_bright[key] = block
        if block.exposure_ns in by_exposure and len(exposures) > 1:
            first = by_exposure[block.exposure_ns].line
            raise ConfigError(
                where,
                f"b {block.exposure_ns:g}",
                f"a second bright block at this exposure (first at line {first}): a descriptor varies "
                "either the exposure (one b block per exposure) or the photons at one exposure",
            )
        by_exposure.setdefault(block.exposure_ns, block)
        if block.exposure_ns not in seen_dark:
            raise ConfigError(where, f"b {block.exposure_ns:g}", "no dark (d) block with two images at this exposure")
    spatial = [b for b in blocks if b.spatial]
    for dark in (True, False):
        kind = [b for b in spatial if b.dark == dark]
        if len(kind) > 1:
            raise ConfigError(
                f"{name}:{kind[1].line}",
                len(kind[1].images),
                f"a second spatial {'dark' if dark else 'bright'} block (first at line {kind[0].line})",
            )
    if len(spatial) == 1 or (len(spatial) == 2 and spatial[0].exposure_ns != spatial[1].exposure_ns):
        raise ConfigError(
            f"{name}:{spatial[-1].line}",
            len(spatial[-1].images),
            "a spatial block needs a bright and a dark stack at the same exposure",
        )


def format_descriptor(desc: Descriptor, comments: tuple[str, ...] = ()) -> str:
    """The descriptor text (numbers written with 9 significant digits: parse ∘ format is exact to that)."""
    out = [f"# {c}" for c in comments]
    out += [f"v {desc.version}", "# n bits width height", f"n {desc.bits} {desc.width} {desc.height}"]
    out += [f"l {name} {value}" for name, value in desc.variables.items()]
    for block in desc.blocks:
        out.append(f"d {block.exposure_ns:.9g}" if block.dark else f"b {block.exposure_ns:.9g} {block.photons:.9g}")
        out += [f"i {name}" for name in block.images]
    return "\n".join(out) + "\n"


class ImageReader:
    """Reads a descriptor's images, checking size, type and range against its ``n`` line."""

    def __init__(self, base: Path, desc: Descriptor):
        self.base = base
        self.shape = (desc.height, desc.width)
        self.full = (1 << desc.bits) - 1
        self._layout: _TiffLayout | None = None  # learnt from the first TIFF tifffile reads

    def path(self, name: str) -> Path:
        return self.base.joinpath(*PureWindowsPath(name).parts)

    def read(self, name: str, out: np.ndarray | None = None) -> np.ndarray:
        """The image ``name``, checked; ``out``: an array of the expected shape and type to read a TIFF into (the
        result may be ``out`` itself: the caller reuses it)."""
        return self._read(name, out)[0]

    def _read(self, name: str, out: np.ndarray | None) -> tuple[np.ndarray, int]:
        """`read`, and the image's largest value (found by the range check: the accumulator need not look again)."""
        path = check_input_file(self.path(name), "image", MAX_BINARY_BYTES, "image")
        image = None
        if path.suffix.lower() in (".tif", ".tiff"):
            image = self._read_tiff(path, out)
        if image is None:
            import cv2

            image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise ConfigError("image", str(path), "unreadable image")
        if image.ndim != 2 or image.dtype.kind not in "ui":
            raise ConfigError(
                "image", str(path), f"expected a monochrome integer image, got {image.dtype}{image.shape}"
            )
        if image.shape != self.shape:
            raise ConfigError(
                "image",
                str(path),
                f"size {image.shape[1]}x{image.shape[0]} differs from the "
                f"descriptor's n line ({self.shape[1]}x{self.shape[0]})",
            )
        top = int(image.max())
        if (image.dtype.kind == "i" and image.min() < 0) or top > self.full:
            raise ConfigError("image", str(path), f"values outside 0..{self.full} (the descriptor's bit depth)")
        return (image if image.dtype.itemsize <= 2 else image.astype(np.uint16 if self.full > 255 else np.uint8)), top

    def _read_tiff(self, path: Path, out: np.ndarray | None) -> np.ndarray | None:
        """A TIFF through tifffile (a plain read into one array: ~10x faster than OpenCV's decoder on uncompressed
        16-bit images; into ``out`` when given and of its shape and type), None where tifffile cannot decode it.
        A file laid out as the first one tifffile read is read at its pixels without parsing it again
        (`_TiffLayout`)."""
        if self._layout is not None:
            image = self._layout.read(path, self.shape, out)
            if image is not None:
                return image
        import tifffile

        try:
            with tifffile.TiffFile(path) as tif:
                page = tif.pages.first
                if len(tif.pages) != 1 or not isinstance(page, tifffile.TiffPage):
                    return tifffile.imread(path)
                fits = out is not None and page.shape == out.shape and page.dtype == out.dtype
                image = page.asarray(out=out if fits else None)
                if self._layout is None and page.shape == self.shape and page.is_final:
                    one_byte = page.dtype is not None and page.dtype.itemsize == 1
                    native = one_byte or tif.byteorder == ("<" if sys.byteorder == "little" else ">")
                    if native and page.samplesperpixel == 1 and image.dtype == page.dtype:
                        self._layout = _TiffLayout.of(path, page.dataoffsets[0], image.nbytes, image.dtype)
                return image
        except (ValueError, KeyError, NotImplementedError, OSError, tifffile.TiffFileError):
            return None

    def stack(
        self, block: Block, clip_dn: float, keep_mean_image: bool = False, work: WorkImages | None = None
    ) -> StackStatistics:
        """`StackStatistics` of the block, its images streamed through an accumulator one at a time, each with the
        largest value its range check found; with ``work``, read into two work images in turn, so that no frame
        costs the page faults of a fresh 10 MB array and each stays unchanged until the next one has been added to
        the accumulator (its ``stable_frames``: a frame waiting for its partner is not copied)."""
        acc = StackAccumulator(clip_dn, keep_mean_image, work=work, stable_frames=work is not None)
        dtype = np.uint16 if self.full > 255 else np.uint8
        buffers = [None, None] if work is None else [work.get(f"read {i}", self.shape, dtype) for i in (0, 1)]
        for i, name in enumerate(block.images):
            acc.add(*self._read(name, buffers[i % 2]))
        return acc.result()

    def statistics(self, blocks: list[Block], clip_dn: float, keep_mean_image: bool = False) -> list[StackStatistics]:
        """`StackStatistics` of each block (`stack`), the blocks spread over `WORKERS` threads (reading and the
        arithmetic release the GIL); memory stays at one accumulator, a frame and the work images of the highpass
        (`WorkImages`, reused) per thread."""
        if len(blocks) < 2 or WORKERS == 1:
            work = WorkImages()
            return [self.stack(b, clip_dn, keep_mean_image, work) for b in blocks]
        local = threading.local()

        def one(block: Block) -> StackStatistics:
            if not hasattr(local, "work"):
                local.work = WorkImages()  # each thread its own, gone with the pool
            return self.stack(block, clip_dn, keep_mean_image, local.work)

        with _opencv_single_threaded(), ThreadPoolExecutor(min(WORKERS, len(blocks))) as pool:
            return list(pool.map(one, blocks))


@dataclass(frozen=True)
class _TiffLayout:
    """Where tifffile found the pixels of a descriptor image: one uncompressed page of ``dtype`` (native byte order)
    stored contiguously, ``offset`` bytes into a file of ``size`` bytes, and the file's other bytes (``head``,
    ``tail``: the header and tags). A file of the same size whose other bytes are the same has the same tags, so its
    pixels are where they were: read there, without tifffile parsing the tags of every image again (0.5 ms a file,
    half of a small descriptor's reading)."""

    size: int
    offset: int
    dtype: np.dtype
    head: bytes
    tail: bytes

    @classmethod
    def of(cls, path: Path, offset: int, nbytes: int, dtype: np.dtype) -> _TiffLayout:
        with path.open("rb") as f:
            head = f.read(offset)
            f.seek(nbytes, os.SEEK_CUR)
            tail = f.read()
        return cls(offset + nbytes + len(tail), offset, dtype, head, tail)

    def read(self, path: Path, shape: tuple[int, int], out: np.ndarray | None) -> np.ndarray | None:
        """The pixels of ``path`` (into ``out`` when of the shape and type) if it is laid out so, else None."""
        try:
            with path.open("rb") as f:
                if os.fstat(f.fileno()).st_size != self.size or f.read(self.offset) != self.head:
                    return None
                fits = out is not None and out.shape == shape and out.dtype == self.dtype and out.flags.c_contiguous
                image = out if out is not None and fits else np.empty(shape, self.dtype)
                if f.readinto(image.data.cast("B")) != image.nbytes or f.read() != self.tail:
                    return None
                return image
        except OSError:
            return None


@contextmanager
def _opencv_single_threaded() -> Iterator[None]:
    """OpenCV's own thread pool off while the blocks are spread over threads: its workers would only wait for CPUs
    the blocks already use (a pair's statistics took 40 ms of CPU with it, 27 ms without, on 2 cores)."""
    import cv2

    previous = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(previous)


def descriptor_clip_level(reader: ImageReader, desc: Descriptor) -> ClipLevel:
    """The clip level from the first image of the brightest temporal bright block (module docstring)."""
    bright = [b for b in desc.blocks if not b.dark]
    fmt = f"Mono{desc.bits}"
    if not bright:
        return clip_level(fmt)
    brightest = max(bright, key=lambda b: (b.photons, b.exposure_ns))
    return clip_level(fmt, image=reader.read(brightest.images[0]))


def photon_transfer_from_descriptor(path: str | Path, pixel_size_um: float | None = None) -> PhotonTransfer:
    """The `PhotonTransfer` of a descriptor dataset (statistics streamed from its images)."""
    path = Path(path)
    desc = parse_descriptor(path)
    reader = ImageReader(path.parent, desc)
    clip = descriptor_clip_level(reader, desc)
    temporal = [b for b in desc.blocks if not b.spatial]
    bright = [b for b in temporal if not b.dark]
    if not bright:
        raise ConfigError(path.name, "b", "no bright (b) blocks with two images")
    dark_blocks = [b for b in temporal if b.dark]
    measured = reader.statistics(dark_blocks + bright, clip.dn)
    darks = {b.exposure_ns: s for b, s in zip(dark_blocks, measured[: len(dark_blocks)], strict=True)}
    stats = measured[len(dark_blocks) :]
    dark_at = [darks[b.exposure_ns] for b in bright]
    arr = lambda seq, name: np.array([getattr(s, name) for s in seq], float)  # noqa: E731
    dark_t = np.array(sorted(darks))
    return PhotonTransfer(
        photons=np.array([b.photons for b in bright]),
        exposure_s=np.array([b.exposure_ns for b in bright]) * 1e-9,
        mean_dn=arr(stats, "mean_dn"),
        temporal_var_dn2=arr(stats, "temporal_var_dn2"),
        frames=arr(stats, "frames"),
        dark_mean_dn=arr(dark_at, "mean_dn"),
        dark_temporal_var_dn2=arr(dark_at, "temporal_var_dn2"),
        dark_frames=arr(dark_at, "frames"),
        spatial=SpatialSplit.of(stats),
        dark_spatial=SpatialSplit.of(dark_at),
        dark=DarkSeries(
            dark_t * 1e-9,
            np.array([darks[t].mean_dn for t in dark_t]),
            np.array([darks[t].temporal_var_dn2 for t in dark_t]),
            np.full(len(dark_t), np.nan),
        ),
        bit_depth=desc.bits,
        saturated_fraction=arr(stats, "saturated_fraction"),
        mean_diff_dn=arr(stats, "mean_diff_dn"),
        stack=_stack(desc, reader, clip),
        width_px=desc.width,
        height_px=desc.height,
        pixels=desc.width * desc.height,
        pixel_area_m2=(pixel_size_um * 1e-6) ** 2 if pixel_size_um else None,
        source=f"descriptor {path}",
        notes=(f"clip level {clip.dn:g} DN ({clip.source})",),
    )


def _stack(desc: Descriptor, reader: ImageReader, clip: ClipLevel) -> NonuniformityStack | None:
    spatial = {b.dark: b for b in desc.blocks if b.spatial}
    if len(spatial) != 2:
        return None
    bright, dark = spatial[False], spatial[True]
    bright_stats, dark_stats = reader.statistics([bright, dark], clip.dn, keep_mean_image=True)
    return NonuniformityStack(bright_stats, dark_stats, bright.photons, bright.exposure_ns * 1e-9)


SHEET_VARIABLES = {
    "vendor": ("vendor", "vendorname"),
    "model": ("model", "modelname", "cameramodel"),
    "serial": ("serial", "serialnumber"),
    "interface": ("interface", "interfacetype"),
    "measured": ("date", "measurementdate"),
}


def sheet_info(desc: Descriptor) -> SheetInfo:
    """The datasheet header from the descriptor's ``l`` variables (names matched case-insensitively)."""
    found = {name.lower(): value for name, value in desc.variables.items()}
    value = {key: str(next((found[n] for n in names if n in found), "—")) for key, names in SHEET_VARIABLES.items()}
    return SheetInfo(
        vendor=value["vendor"],
        model=value["model"],
        serial=value["serial"],
        measured=value["measured"],
        interface=value["interface"],
    )
