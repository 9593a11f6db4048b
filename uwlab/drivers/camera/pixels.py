"""Monochrome pixel formats: PFNC codes, bit depths, packing and vectorised unpacking.

Layouts follow the GenICam Pixel Format Naming Convention (PFNC 2.x) and, for the two legacy
GigE Vision ``*Packed`` formats, the GigE Vision 1.2 specification (section "Pixel formats"):

* ``Mono8``: one byte per pixel.
* ``Mono10``, ``Mono12``, ``Mono14``, ``Mono16``: one little-endian 16-bit word per pixel, value in the LSBs.
* ``Mono10p``, ``Mono12p``: LSB-first bit stream (pixel 0 in the lowest bits of byte 0);
  ``Mono10p`` packs 4 pixels in 5 bytes, ``Mono12p`` 2 pixels in 3 bytes.
* ``Mono10Packed``, ``Mono12Packed`` (GigE Vision legacy): 2 pixels in 3 bytes; bytes 0 and 2
  hold the 8 MSBs of pixel 0 and 1, byte 1 holds their LSBs (pixel 0 in bits 0-3, pixel 1 in 4-7).

Every decoded image is a C-contiguous ``uint8`` (Mono8) or ``uint16`` array of shape (height, width).
"""

from __future__ import annotations

from dataclasses import dataclass

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
    )
}
_BY_CODE = {pf.code: pf for pf in PIXEL_FORMATS.values()}


def pixel_format(name_or_code: str | int) -> PixelFormat:
    """Look a format up by PFNC name or code; unknown formats raise `ConfigError`."""
    found = _BY_CODE.get(name_or_code) if isinstance(name_or_code, int) else PIXEL_FORMATS.get(name_or_code)
    if found is None:
        shown = f"0x{name_or_code:08X}" if isinstance(name_or_code, int) else name_or_code
        raise ConfigError("pixel_format", shown, f"unsupported; supported: {', '.join(PIXEL_FORMATS)}")
    return found


def _groups(raw: np.ndarray, group_bytes: int, n_pixels: int, pixels_per_group: int) -> np.ndarray:
    n_groups = -(-n_pixels // pixels_per_group)
    need = n_groups * group_bytes
    wire_bytes = -(-n_pixels * group_bytes // pixels_per_group)
    if raw.size < wire_bytes:
        raise ConfigError("payload", raw.size, f"too short for {n_pixels} pixels")
    if raw.size < need:
        raw = np.concatenate([raw, np.zeros(need - raw.size, np.uint8)])
    return raw[:need].reshape(n_groups, group_bytes).astype(np.uint16)


def _unpack_10p(raw: np.ndarray, n: int) -> np.ndarray:
    b = _groups(raw, 5, n, 4)
    out = np.empty((b.shape[0], 4), np.uint16)
    out[:, 0] = b[:, 0] | ((b[:, 1] & 0x03) << 8)
    out[:, 1] = (b[:, 1] >> 2) | ((b[:, 2] & 0x0F) << 6)
    out[:, 2] = (b[:, 2] >> 4) | ((b[:, 3] & 0x3F) << 4)
    out[:, 3] = (b[:, 3] >> 6) | (b[:, 4] << 2)
    return out.reshape(-1)[:n]


def _unpack_12p(raw: np.ndarray, n: int) -> np.ndarray:
    b = _groups(raw, 3, n, 2)
    out = np.empty((b.shape[0], 2), np.uint16)
    out[:, 0] = b[:, 0] | ((b[:, 1] & 0x0F) << 8)
    out[:, 1] = (b[:, 1] >> 4) | (b[:, 2] << 4)
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
    return out.reshape(-1)[: PIXEL_FORMATS["Mono10p"].payload_bytes(img.size, 1)]


def _pack_12p(img: np.ndarray) -> np.ndarray:
    p = _padded(img, 2).reshape(-1, 2)
    out = np.empty((p.shape[0], 3), np.uint8)
    out[:, 0] = p[:, 0] & 0xFF
    out[:, 1] = (p[:, 0] >> 8) | ((p[:, 1] & 0x0F) << 4)
    out[:, 2] = p[:, 1] >> 4
    return out.reshape(-1)[: PIXEL_FORMATS["Mono12p"].payload_bytes(img.size, 1)]


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


_UNPACK = {
    "Mono10p": _unpack_10p,
    "Mono12p": _unpack_12p,
    "Mono10Packed": lambda raw, n: _unpack_legacy(raw, n, 2),
    "Mono12Packed": lambda raw, n: _unpack_legacy(raw, n, 4),
}
_PACK = {
    "Mono10p": _pack_10p,
    "Mono12p": _pack_12p,
    "Mono10Packed": lambda img: _pack_legacy(img, 2),
    "Mono12Packed": lambda img: _pack_legacy(img, 4),
}


def pack(image: np.ndarray, fmt: PixelFormat) -> np.ndarray:
    """Encode a decoded image into the wire bytes of ``fmt`` (1-D ``uint8``)."""
    if fmt.name in _PACK:
        return _PACK[fmt.name](image)
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
    if fmt.name in _UNPACK:
        return _UNPACK[fmt.name](data, n).reshape(height, width)
    need = n * fmt.dtype.itemsize
    if data.size < need:
        raise ConfigError("payload", data.size, f"too short for {width}x{height} {fmt.name} ({need} bytes)")
    return (
        data[:need]
        .view("<u2" if fmt.dtype.itemsize == 2 else np.uint8)
        .astype(fmt.dtype, copy=False)
        .reshape(height, width)
    )
