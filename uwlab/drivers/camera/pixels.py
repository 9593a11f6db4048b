"""Monochrome and Bayer (raw colour) pixel formats: PFNC codes, bit depths, packing and vectorised unpacking.

Layouts follow the GenICam Pixel Format Naming Convention (PFNC 2.x) and, for the legacy
GigE Vision ``*Packed`` formats, the GigE Vision 1.2 specification (section "Pixel formats"):

* ``Mono8``: one byte per pixel.
* ``Mono10``, ``Mono12``, ``Mono14``, ``Mono16``: one little-endian 16-bit word per pixel, value in the LSBs.
* ``Mono10p``, ``Mono12p``: LSB-first bit stream (pixel 0 in the lowest bits of byte 0);
  ``Mono10p`` packs 4 pixels in 5 bytes, ``Mono12p`` 2 pixels in 3 bytes.
* ``Mono10Packed``, ``Mono12Packed`` (GigE Vision legacy): 2 pixels in 3 bytes; bytes 0 and 2
  hold the 8 MSBs of pixel 0 and 1, byte 1 holds their LSBs (pixel 0 in bits 0-3, pixel 1 in 4-7).

A Bayer format ``Bayer<XY><n>[p|Packed]`` is packed exactly as ``Mono<n>[p|Packed]`` (PFNC: the packing is
independent of the colour filter); ``XY`` names the filters of the first two pixels of the first row, the second
row holding the other two (PFNC "Bayer" components: ``RG`` is R G / G B, ``GR`` is G R / B G, ``GB`` is
G B / R G, ``BG`` is B G / G R). PFNC defines Bayer 8, 10, 12 and 16 bits unpacked, 10p and 12p, and the GigE
Vision legacy 10Packed and 12Packed; `bayer_sites` gives each colour's positions in the 2 × 2 cell.

Every decoded image is a C-contiguous ``uint8`` (8-bit formats) or ``uint16`` array of shape (height, width):
a Bayer image stays the raw mosaic (no demosaicing: each pixel is its own filter's measurement).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from uwlab.errors import ConfigError


@dataclass(frozen=True)
class PixelFormat:
    """One pixel format: PFNC ``name``, 32-bit ``code``, significant ``bits``, ``bits_per_pixel``
    on the wire, and the numpy dtype of the decoded image."""

    name: str
    code: int
    bits: int
    bits_per_pixel: int
    bayer: str | None = None

    @property
    def packing(self) -> str:
        """``""`` (one byte or one little-endian word per pixel), ``"p"`` (PFNC LSB-first bit stream) or
        ``"Packed"`` (GigE Vision legacy)."""
        return "Packed" if self.name.endswith("Packed") else "p" if self.name.endswith("p") else ""

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(np.uint8 if self.bits_per_pixel == 8 else np.uint16)

    @property
    def max_value(self) -> int:
        return (1 << self.bits) - 1

    def payload_bytes(self, width: int, height: int) -> int:
        """Bytes of one frame on the wire (a partial last group is padded to whole bytes)."""
        return -(-width * height * self.bits_per_pixel // 8)


PIXEL_FORMATS: dict[str, PixelFormat] = {
    pf.name: pf
    for pf in (
        PixelFormat("Mono8", 0x01080001, 8, 8),
        PixelFormat("Mono10", 0x01100003, 10, 16),
        PixelFormat("Mono10p", 0x010A0046, 10, 10),
        PixelFormat("Mono10Packed", 0x010C0004, 10, 12),
        PixelFormat("Mono12", 0x01100005, 12, 16),
        PixelFormat("Mono12p", 0x010C0047, 12, 12),
        PixelFormat("Mono12Packed", 0x010C0006, 12, 12),
        PixelFormat("Mono14", 0x01100025, 14, 16),
        PixelFormat("Mono16", 0x01100007, 16, 16),
        # PFNC 2.x Bayer codes, per layout: (8, 10, 12, 16, 10p, 12p, 10Packed, 12Packed)
        *(
            PixelFormat(f"Bayer{layout}{suffix}", code, bits, wire, layout)
            for layout, codes in (
                (
                    "GR",
                    (0x01080008, 0x0110000C, 0x01100010, 0x0110002E, 0x010A0056, 0x010C0057, 0x010C0026, 0x010C002A),
                ),
                (
                    "RG",
                    (0x01080009, 0x0110000D, 0x01100011, 0x0110002F, 0x010A0058, 0x010C0059, 0x010C0027, 0x010C002B),
                ),
                (
                    "GB",
                    (0x0108000A, 0x0110000E, 0x01100012, 0x01100030, 0x010A0054, 0x010C0055, 0x010C0028, 0x010C002C),
                ),
                (
                    "BG",
                    (0x0108000B, 0x0110000F, 0x01100013, 0x01100031, 0x010A0052, 0x010C0053, 0x010C0029, 0x010C002D),
                ),
            )
            for (suffix, bits, wire), code in zip(
                (
                    ("8", 8, 8),
                    ("10", 10, 16),
                    ("12", 12, 16),
                    ("16", 16, 16),
                    ("10p", 10, 10),
                    ("12p", 12, 12),
                    ("10Packed", 10, 12),
                    ("12Packed", 12, 12),
                ),
                codes,
                strict=True,
            )
        ),
    )
}
MONO_FORMATS = tuple(name for name, pf in PIXEL_FORMATS.items() if pf.bayer is None)
BayerLayout = Literal["RG", "GR", "GB", "BG"]
BAYER_LAYOUTS: tuple[str, ...] = get_args(BayerLayout)
_BY_CODE = {pf.code: pf for pf in PIXEL_FORMATS.values()}


def pixel_format(name_or_code: str | int) -> PixelFormat:
    """Look a format up by PFNC name or code; unknown formats raise `ConfigError`."""
    found = _BY_CODE.get(name_or_code) if isinstance(name_or_code, int) else PIXEL_FORMATS.get(name_or_code)
    if found is None:
        shown = f"0x{name_or_code:08X}" if isinstance(name_or_code, int) else name_or_code
        raise ConfigError("pixel_format", shown, f"unsupported; supported: {', '.join(PIXEL_FORMATS)}")
    return found


def bayer_formats(layout: str) -> tuple[str, ...]:
    """Every Bayer format of one colour filter ``layout`` (``"RG"``, ``"GR"``, ``"GB"``, ``"BG"``)."""
    return tuple(name for name, pf in PIXEL_FORMATS.items() if pf.bayer == layout)


def bayer_sites(layout: str, x0: int = 0, y0: int = 0) -> dict[str, tuple[tuple[int, int], ...]]:
    """The (row, column) offsets in the repeating 2 × 2 cell of each colour, ``{"R": ..., "G": (two), "B": ...}``,
    for a mosaic of ``layout`` seen from pixel (x0, y0) on (a crop starting there: odd offsets shift the phase).

    >>> bayer_sites("RG")
    {'R': ((0, 0),), 'G': ((0, 1), (1, 0)), 'B': ((1, 1),)}
    >>> bayer_sites("RG", x0=1)
    {'R': ((0, 1),), 'G': ((0, 0), (1, 1)), 'B': ((1, 0),)}
    """
    if layout not in BAYER_LAYOUTS:
        raise ConfigError("bayer", layout, f"expected one of {', '.join(BAYER_LAYOUTS)}")
    first, second = layout, {"R": "B", "B": "R", "G": "G"}[layout[1]] + {"R": "B", "B": "R", "G": "G"}[layout[0]]
    colours = {(0, 0): first[0], (0, 1): first[1], (1, 0): second[0], (1, 1): second[1]}
    sites: dict[str, list[tuple[int, int]]] = {"R": [], "G": [], "B": []}
    for (row, col), colour in colours.items():
        sites[colour].append(((row - y0) % 2, (col - x0) % 2))
    return {colour: tuple(sorted(cells)) for colour, cells in sites.items()}


def bayer_mosaic(layout: str, planes: dict[str, np.ndarray]) -> np.ndarray:
    """The raw frame of a ``layout`` colour filter array: each site taken from its colour's plane (``planes`` maps
    ``"R"``, ``"G"`` and ``"B"`` to full frames of one shape, e.g. what each filter would pass at every pixel).

    >>> bayer_mosaic("RG", {c: np.full((2, 4), v) for c, v in zip("RGB", (1, 2, 3))})
    array([[1, 2, 1, 2],
           [2, 3, 2, 3]])
    """
    out = np.empty_like(planes["G"])
    for colour, cells in bayer_sites(layout).items():
        for row, col in cells:
            out[row::2, col::2] = planes[colour][row::2, col::2]
    return out


def _whole_groups(raw: np.ndarray, group_bytes: int, n_pixels: int, pixels_per_group: int) -> tuple[np.ndarray, int]:
    """The payload and its number of groups, a partial last group padded with zeros (a copy only then)."""
    n_groups = -(-n_pixels // pixels_per_group)
    need = n_groups * group_bytes
    wire_bytes = -(-n_pixels * group_bytes // pixels_per_group)
    if raw.size < wire_bytes:
        raise ConfigError("payload", raw.size, f"too short for {n_pixels} pixels")
    if raw.size < need:
        raw = np.concatenate([raw, np.zeros(need - raw.size, np.uint8)])
    return raw, n_groups


def _groups(raw: np.ndarray, group_bytes: int, n_pixels: int, pixels_per_group: int) -> np.ndarray:
    raw, n_groups = _whole_groups(raw, group_bytes, n_pixels, pixels_per_group)
    return raw[: n_groups * group_bytes].reshape(n_groups, group_bytes).astype(np.uint16)


def _words(raw: np.ndarray, n_groups: int, group_bytes: int, offset: int) -> np.ndarray:
    """The little-endian 16-bit word at byte ``offset`` of every group: a strided view, nothing copied."""
    return np.ndarray((n_groups,), "<u2", raw, offset, (group_bytes,))


def _unpack_10p(raw: np.ndarray, n: int) -> np.ndarray:
    """4 pixels in 5 bytes: pixel k is bits 10k..10k+9 of the group, i.e. in the 16-bit word at byte k, shifted
    right by 2k; one pass per pixel of the group straight from the payload (no widened copy of it)."""
    raw, n_groups = _whole_groups(raw, 5, n, 4)
    out = np.empty((n_groups, 4), np.uint16)
    np.bitwise_and(_words(raw, n_groups, 5, 0), 0x03FF, out=out[:, 0])
    for k in (1, 2):
        np.right_shift(_words(raw, n_groups, 5, k), 2 * k, out=out[:, k])
        out[:, k] &= 0x03FF
    np.right_shift(_words(raw, n_groups, 5, 3), 6, out=out[:, 3])
    return out.reshape(-1)[:n]


def _unpack_12p(raw: np.ndarray, n: int) -> np.ndarray:
    """2 pixels in 3 bytes: pixel 0 is the low 12 bits of the word at byte 0, pixel 1 the high 12 of the word at
    byte 1."""
    raw, n_groups = _whole_groups(raw, 3, n, 2)
    out = np.empty((n_groups, 2), np.uint16)
    np.bitwise_and(_words(raw, n_groups, 3, 0), 0x0FFF, out=out[:, 0])
    np.right_shift(_words(raw, n_groups, 3, 1), 4, out=out[:, 1])
    return out.reshape(-1)[:n]


def _unpack_legacy(raw: np.ndarray, n: int, lsb_bits: int) -> np.ndarray:
    b = _groups(raw, 3, n, 2)
    mask = (1 << lsb_bits) - 1
    out = np.empty((b.shape[0], 2), np.uint16)
    out[:, 0] = (b[:, 0] << lsb_bits) | (b[:, 1] & mask)
    out[:, 1] = (b[:, 2] << lsb_bits) | ((b[:, 1] >> 4) & mask)
    return out.reshape(-1)[:n]


def _pack_10p(img: np.ndarray) -> np.ndarray:
    p = _padded(img, 4).reshape(-1, 4)
    out = np.empty((p.shape[0], 5), np.uint8)
    out[:, 0] = p[:, 0] & 0xFF
    out[:, 1] = (p[:, 0] >> 8) | ((p[:, 1] & 0x3F) << 2)
    out[:, 2] = (p[:, 1] >> 6) | ((p[:, 2] & 0x0F) << 4)
    out[:, 3] = (p[:, 2] >> 4) | ((p[:, 3] & 0x03) << 6)
    out[:, 4] = p[:, 3] >> 2
    return out.reshape(-1)[: -(-img.size * 10 // 8)]


def _pack_12p(img: np.ndarray) -> np.ndarray:
    p = _padded(img, 2).reshape(-1, 2)
    out = np.empty((p.shape[0], 3), np.uint8)
    out[:, 0] = p[:, 0] & 0xFF
    out[:, 1] = (p[:, 0] >> 8) | ((p[:, 1] & 0x0F) << 4)
    out[:, 2] = p[:, 1] >> 4
    return out.reshape(-1)[: -(-img.size * 12 // 8)]


def _pack_legacy(img: np.ndarray, lsb_bits: int) -> np.ndarray:
    p = _padded(img, 2).reshape(-1, 2)
    mask = (1 << lsb_bits) - 1
    out = np.empty((p.shape[0], 3), np.uint8)
    out[:, 0] = p[:, 0] >> lsb_bits
    out[:, 1] = (p[:, 0] & mask) | ((p[:, 1] & mask) << 4)
    out[:, 2] = p[:, 1] >> lsb_bits
    return out.reshape(-1)[: -(-img.size * 12 // 8)]


def _padded(img: np.ndarray, group: int) -> np.ndarray:
    flat = np.ascontiguousarray(img, dtype=np.uint16).reshape(-1)
    extra = (-flat.size) % group
    return np.concatenate([flat, np.zeros(extra, np.uint16)]) if extra else flat


# (bits, packing) -> codec; Mono and Bayer formats share them
_UNPACK = {
    (10, "p"): _unpack_10p,
    (12, "p"): _unpack_12p,
    (10, "Packed"): lambda raw, n: _unpack_legacy(raw, n, 2),
    (12, "Packed"): lambda raw, n: _unpack_legacy(raw, n, 4),
}
_PACK = {
    (10, "p"): _pack_10p,
    (12, "p"): _pack_12p,
    (10, "Packed"): lambda img: _pack_legacy(img, 2),
    (12, "Packed"): lambda img: _pack_legacy(img, 4),
}


def pack(image: np.ndarray, fmt: PixelFormat) -> np.ndarray:
    """Encode a decoded image into the wire bytes of ``fmt`` (1-D ``uint8``)."""
    if fmt.packing:
        return _PACK[fmt.bits, fmt.packing](image)
    return np.ascontiguousarray(image, dtype=fmt.dtype).reshape(-1).view(np.uint8)


def unpack(raw: np.ndarray | bytes | memoryview, fmt: PixelFormat, width: int, height: int) -> np.ndarray:
    """Decode wire bytes of ``fmt`` into a (height, width) ``uint8``/``uint16`` image.

    A 2-D array already of the decoded dtype and shape is returned unchanged (in-process sources).
    """
    if isinstance(raw, np.ndarray) and raw.ndim == 2:
        if raw.shape != (height, width) or raw.dtype != fmt.dtype:
            raise ConfigError("image", f"{raw.dtype}{raw.shape}", f"expected {fmt.dtype}({height}, {width})")
        return raw
    data = np.frombuffer(raw, np.uint8) if not isinstance(raw, np.ndarray) else raw.reshape(-1).view(np.uint8)
    n = width * height
    if fmt.packing:
        return _UNPACK[fmt.bits, fmt.packing](data, n).reshape(height, width)
    need = n * fmt.dtype.itemsize
    if data.size < need:
        raise ConfigError("payload", data.size, f"too short for {width}x{height} {fmt.name} ({need} bytes)")
    return (
        data[:need]
        .view("<u2" if fmt.dtype.itemsize == 2 else np.uint8)
        .astype(fmt.dtype, copy=False)
        .reshape(height, width)
    )
