"""EMVA 1288 descriptor files: parse/format round trip, malformed input, export -> import -> same results."""
import numpy as np
import pytest
import tifffile

from uwlab.errors import ConfigError
from uwlab.experiments.emva.analysis import characterize
from uwlab.experiments.emva.descriptor import (
    Block, Descriptor, format_descriptor, parse_descriptor, photon_transfer_from_descriptor, write_descriptor,
)
from tests.sim.test_emva_analysis import model_transfer


def test_parse_format_round_trip(tmp_path):
    desc = Descriptor("4.0", 12, 64, 48, (
        Block(False, 40000.0, 120.125, ("images/a.tif", "images/b.tif")),
        Block(True, 40000.0, 0.0, ("images/c.tif", "images/d.tif")),
        Block(False, 80000.0, 240.25, tuple(f"images/s{i}.tif" for i in range(5))),
    ), {"InterfaceType": "Gigabit Ethernet"})
    path = tmp_path / "d.txt"
    path.write_text(format_descriptor(desc, ("a comment",)))
    assert parse_descriptor(path) == desc
    assert parse_descriptor(path).blocks[2].spatial


def test_reference_style_lines(tmp_path):
    path = tmp_path / "EMVA1288_Data.txt"
    path.write_text("# n bits width height\nv 3.0\nn 8 4 4\nb 1000,5 12,5\ni images\\x1.png\ni images\\x2.png\n")
    desc = parse_descriptor(path)
    assert (desc.bits, desc.width, desc.height, desc.version) == (8, 4, 4, "3.0")
    assert desc.blocks[0].exposure_ns == 1000.5 and desc.blocks[0].photons == 12.5


@pytest.mark.parametrize("text, where", [
    ("v 4.0\nb 1 2\ni a.tif\n", "d.txt:end"),
    ("v 4.0\nn 12 4 4\nx 1 2\n", "d.txt:3"),
    ("v 4.0\nn 12 4 4\nb one 2\n", "d.txt:3"),
    ("v 4.0\nb 1 2\ni a.tif\ni b.tif\n", "d.txt"),
])
def test_malformed_descriptors_name_file_and_line(tmp_path, text, where):
    path = tmp_path / "d.txt"
    path.write_text(text)
    with pytest.raises(ConfigError, match=where):
        parse_descriptor(path)


def test_missing_dark_block_is_refused(tmp_path):
    for name in ("a.tif", "b.tif"):
        tifffile.imwrite(tmp_path / name, np.full((8, 8), 100, np.uint16))
    path = tmp_path / "d.txt"
    path.write_text("v 4.0\nn 12 8 8\nb 1000 10\ni a.tif\ni b.tif\n")
    with pytest.raises(ConfigError, match="no dark images"):
        photon_transfer_from_descriptor(path)


def test_export_import_round_trip(tmp_path):
    pt = model_transfer(n=30)
    path = write_descriptor(pt, tmp_path / "desc", shape=(96, 96), seed=1)
    back = photon_transfer_from_descriptor(path)
    np.testing.assert_allclose(back.photons, np.sort(pt.photons), rtol=1e-8)
    np.testing.assert_allclose(back.exposure_s, np.sort(pt.exposure_s), rtol=1e-8)
    assert back.spatial is not None and back.spatial.frames == 16
    a, b = characterize(pt).values, characterize(back).values
    assert b["K_dn_per_e"] == pytest.approx(a["K_dn_per_e"], rel=0.02)
    assert b["quantum_efficiency"] == pytest.approx(a["quantum_efficiency"], rel=0.02)
    assert b["dark_noise_e"] == pytest.approx(a["dark_noise_e"], rel=0.05)
    assert b["saturation_e"] == pytest.approx(a["saturation_e"], rel=0.02)
    assert b["dark_current_e_per_s"] == pytest.approx(a["dark_current_e_per_s"], rel=0.1)
    assert b["dsnu_e"] == pytest.approx(a["dsnu_e"], rel=0.1)
    assert b["prnu_percent"] == pytest.approx(a["prnu_percent"], rel=0.1)
    assert "SYNTHETIC" in path.read_text()
    with pytest.raises(ConfigError, match="refusing to overwrite"):
        write_descriptor(pt, tmp_path / "desc")
