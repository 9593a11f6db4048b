"""Pixel formats: packing round trips, byte layouts against an independent bit-stream oracle."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uwlab.drivers.camera.pixels import PIXEL_FORMATS, pack, pixel_format, unpack
from uwlab.errors import ConfigError


def lsb_first_bitstream(values: np.ndarray, bits: int) -> np.ndarray:
    """PFNC ``*p`` layout built bit by bit: pixel 0 in the lowest bits of byte 0."""
    bit_matrix = (values[:, None].astype(np.uint32) >> np.arange(bits)) & 1
    return np.packbits(bit_matrix.reshape(-1).astype(np.uint8), bitorder="little")


@given(st.sampled_from(list(PIXEL_FORMATS)), st.integers(1, 9), st.integers(1, 7), st.integers(0, 2**32 - 1))
@settings(max_examples=120, deadline=None)
def test_pack_unpack_round_trip(name, width, height, seed):
    fmt = pixel_format(name)
    image = np.random.default_rng(seed).integers(0, fmt.max_value + 1, (height, width)).astype(fmt.dtype)
    wire = pack(image, fmt)
    assert wire.dtype == np.uint8 and wire.size == fmt.payload_bytes(width, height)
    decoded = unpack(wire.tobytes(), fmt, width, height)
    assert decoded.dtype == fmt.dtype and decoded.shape == (height, width)
    np.testing.assert_array_equal(decoded, image)


@pytest.mark.parametrize("name,bits", [("Mono10p", 10), ("Mono12p", 12)])
def test_pfnc_p_formats_match_lsb_first_bitstream(name, bits):
    values = np.random.default_rng(3).integers(0, 2**bits, 37).astype(np.uint16)
    np.testing.assert_array_equal(pack(values.reshape(1, -1), pixel_format(name)), lsb_first_bitstream(values, bits))


@pytest.mark.parametrize("name,bits", [("Mono10p", 10), ("Mono12p", 12)])
@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 37, 4099])
def test_pfnc_p_formats_decode_the_lsb_first_bitstream(name, bits, n):
    fmt = pixel_format(name)
    values = np.random.default_rng(n).integers(0, 2**bits, n).astype(np.uint16)
    wire = lsb_first_bitstream(values, bits)
    np.testing.assert_array_equal(unpack(wire.tobytes(), fmt, n, 1)[0], values)
    # an odd start address and trailing bytes (a buffer's chunk data, a partial last group's padding) change nothing
    shifted = np.concatenate([[0xFF], wire, np.full(7, 0xFF)]).astype(np.uint8)[1:]
    np.testing.assert_array_equal(unpack(shifted, fmt, n, 1)[0], values)


def test_known_byte_layouts():
    two = np.array([[0x123, 0x456]], np.uint16)
    assert pack(two, pixel_format("Mono12p")).tolist() == [0x23, 0x61, 0x45]
    assert pack(two, pixel_format("Mono12Packed")).tolist() == [0x12, 0x63, 0x45]
    assert pack(np.array([[0x2A5, 0x15A]], np.uint16), pixel_format("Mono10Packed")).tolist() == [0xA9, 0x21, 0x56]
    assert pack(np.array([[1, 2, 3, 4]], np.uint16), pixel_format("Mono10p")).tolist() == [0x01, 0x08, 0x30, 0x00, 0x01]
    assert unpack(bytes([0x34, 0x12]), pixel_format("Mono16"), 1, 1)[0, 0] == 0x1234


def test_pfnc_codes_and_dtypes():
    assert pixel_format("Mono8").code == 0x01080001 and pixel_format(0x01100007).name == "Mono16"
    assert pixel_format("Mono12p").dtype == np.uint16 and pixel_format("Mono8").dtype == np.uint8


def test_unsupported_format_and_short_payload_raise():
    with pytest.raises(ConfigError, match="RGB8.*supported"):
        pixel_format("RGB8")
    with pytest.raises(ConfigError, match="too short"):
        unpack(bytes(10), pixel_format("Mono12p"), 4, 4)
    with pytest.raises(ConfigError, match="too short"):
        unpack(bytes(10), pixel_format("Mono16"), 4, 4)
