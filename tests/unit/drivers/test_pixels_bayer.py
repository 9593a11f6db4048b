"""Bayer pixel formats: PFNC codes against Aravis's own table, packing shared with Mono, colour sites per layout."""

from __future__ import annotations

import re

import gi
import numpy as np
import pytest

from uwlab.drivers.camera.pixels import (
    BAYER_LAYOUTS,
    PIXEL_FORMATS,
    bayer_formats,
    bayer_sites,
    pack,
    pixel_format,
    unpack,
)

gi.require_version("Aravis", "0.8")
from gi.repository import Aravis  # noqa: E402

# PFNC's 2 x 2 cells written out (row 0, row 1), independent of bayer_sites' construction
CELLS = {"RG": ("RG", "GB"), "GR": ("GR", "BG"), "GB": ("GB", "RG"), "BG": ("BG", "GR")}


def aravis_constant(name: str) -> int:
    """Aravis's ARV_PIXEL_FORMAT_* value for a PFNC name (BayerRG10p -> PIXEL_FORMAT_BAYER_RG_10P)."""
    m = re.fullmatch(r"(Mono|Bayer)([A-Z]{2})?(\d+)(p|Packed)?", name)
    kind, layout, bits, packing = m.groups()
    parts = [kind.upper(), *([layout] if layout else []), bits + ("P" if packing == "p" else "")]
    if packing == "Packed":
        parts.append("PACKED")
    return int(getattr(Aravis, "PIXEL_FORMAT_" + "_".join(parts)))


@pytest.mark.parametrize("name", [n for n in PIXEL_FORMATS if n not in ("Mono10p", "Mono12p")])  # not in Aravis 0.8
def test_codes_match_aravis(name):
    assert PIXEL_FORMATS[name].code == aravis_constant(name)
    assert pixel_format(aravis_constant(name)).name == name


def test_every_layout_has_the_pfnc_depths_and_packings():
    for layout in BAYER_LAYOUTS:
        assert {n.removeprefix(f"Bayer{layout}") for n in bayer_formats(layout)} == {
            "8",
            "10",
            "12",
            "16",
            "10p",
            "12p",
            "10Packed",
            "12Packed",
        }


@pytest.mark.parametrize("depth", ["10", "12", "10p", "12p", "10Packed", "12Packed", "16"])
def test_bayer_packs_like_mono_and_round_trips(depth):
    mono = pixel_format(f"Mono{depth}")
    image = np.random.default_rng(7).integers(0, mono.max_value + 1, (6, 10)).astype(mono.dtype)
    for layout in BAYER_LAYOUTS:
        fmt = pixel_format(f"Bayer{layout}{depth}")
        wire = pack(image, fmt)
        np.testing.assert_array_equal(wire, pack(image, mono))
        np.testing.assert_array_equal(unpack(wire.tobytes(), fmt, 10, 6), image)


@pytest.mark.parametrize("layout", BAYER_LAYOUTS)
def test_sites_follow_the_pfnc_cell(layout):
    sites = bayer_sites(layout)
    for row in range(2):
        for col in range(2):
            assert (row, col) in sites[CELLS[layout][row][col]]
    assert sorted(len(v) for v in sites.values()) == [1, 1, 2]


@pytest.mark.parametrize("layout", BAYER_LAYOUTS)
def test_a_crop_at_odd_offsets_sees_the_neighbouring_layout(layout):
    """Starting one pixel right (or down) of a cell reads its row (or rows) shifted: the layout named by that cell."""
    for x0, y0 in ((1, 0), (0, 1), (1, 1)):
        rows = CELLS[layout][y0:] + CELLS[layout][:y0]
        seen = rows[0][x0:] + rows[0][:x0]
        assert bayer_sites(layout, x0, y0) == bayer_sites(seen)
