"""EMVA 1288 descriptor files: parse/format round trip, every refusal naming the file and line (issue 16: bright blocks
that mix the exposure methods, negative exposures, unsupported bit depths, non-finite photons ...), image checks, and
export -> import -> the same results."""

import numpy as np
import pytest
import tifffile
from hypothesis import given, settings
from hypothesis import strategies as st

from uwlab.errors import ConfigError
from uwlab.experiments.emva.analysis import characterize
from uwlab.experiments.emva.descriptor import (
    Block,
    Descriptor,
    format_descriptor,
    ImageReader,
    parse_descriptor,
    photon_transfer_from_descriptor,
)
from uwlab.experiments.emva.export import write_descriptor
from uwlab.experiments.emva.simulate import DirectBench
from uwlab.sim.devices.camera import SimTruth
from uwlab.model.sensor import load_sensor_profile


def test_parse_format_round_trip(tmp_path):
    desc = Descriptor(
        "4.0",
        12,
        64,
        48,
        (
            Block(False, 40000.0, 120.125, ("images/a.tif", "images/b.tif")),
            Block(True, 40000.0, 0.0, ("images/c.tif", "images/d.tif")),
            Block(False, 80000.0, 240.25, tuple(f"images/s{i}.tif" for i in range(5))),
            Block(True, 80000.0, 0.0, tuple(f"images/t{i}.tif" for i in range(5))),
        ),
        {"InterfaceType": "Gigabit Ethernet"},
    )
    path = tmp_path / "d.txt"
    path.write_text(format_descriptor(desc, ("a comment",)))
    assert parse_descriptor(path) == desc
    assert parse_descriptor(path).blocks[2].spatial


def test_reference_style_lines(tmp_path):
    path = tmp_path / "EMVA1288_Data.txt"
    path.write_text(
        "# n bits width height\nv 3.0\nn 8 4 4 0\nb 1000,5 12,5\ni images\\x1.png\ni images\\x2.png\n"
        "d 1000,5\ni images\\x3.png\ni images\\x4.png\n"
    )
    desc = parse_descriptor(path)
    assert (desc.bits, desc.width, desc.height, desc.version) == (8, 4, 4, "3.0")
    assert desc.blocks[0].exposure_ns == 1000.5 and desc.blocks[0].photons == 12.5


B1 = "b 1000 10\ni a.tif\ni b.tif\n"
D1 = "d 1000\ni c.tif\ni d.tif\n"
HEAD = "v 4.0\nn 12 8 8\n"


@pytest.mark.parametrize(
    "text, where, words",
    [
        ("v 4.0\nb 1 2\ni a.tif\n", "d.txt:2", "two 'i' image lines"),
        (HEAD + "x 1 2\n", "d.txt:3", "expected 'v'"),
        (HEAD + "b one 2\n", "d.txt:3", "not a number"),
        ("v 4.0\nb 1 2\ni a.tif\ni b.tif\n", "d.txt", "missing 'n"),
        ("v 4.0\nn 64 8 8\n" + B1 + D1, "d.txt:2", "bits"),
        ("v 4.0\nn 12 8.5 8\n" + B1 + D1, "d.txt:2", "width"),
        ("v 4.0\nn 12 0 8\n" + B1 + D1, "d.txt:2", "width"),
        (HEAD + "b -1000 10\ni a.tif\ni b.tif\n" + D1, "d.txt:3", "exposure [ns]: must be > 0"),
        (HEAD + "b 1000 nan\ni a.tif\ni b.tif\n" + D1, "d.txt:3", "photons: not a finite number"),
        (HEAD + "b 1000 inf\ni a.tif\ni b.tif\n" + D1, "d.txt:3", "photons: not a finite number"),
        (HEAD + "b 1000 -5\ni a.tif\ni b.tif\n" + D1, "d.txt:3", "photons: must be > 0"),
        (HEAD + "d -3\ni a.tif\ni b.tif\n", "d.txt:3", "must be > 0"),
        (HEAD + B1 + "b 1000 10\ni e.tif\ni f.tif\n" + D1, "d.txt:6", "same bright measurement"),
        (
            HEAD
            + B1
            + "b 1000 20\ni e.tif\ni f.tif\nb 2000 20\ni g.tif\ni h.tif\n"
            + D1
            + "d 2000\ni x.tif\ni y.tif\n",
            "d.txt:6",
            "either the exposure",
        ),
        (HEAD + B1 + D1 + "d 1000\ni e.tif\ni f.tif\n", "d.txt:9", "second dark block"),
        (HEAD + B1, "d.txt:3", "no dark (d) block"),
        (HEAD + B1 + D1 + "b 1000 10\ni s1\ni s2\ni s3\n", "d.txt:9", "bright and a dark stack"),
    ],
)
def test_malformed_descriptors_name_file_and_line(tmp_path, text, where, words):
    path = tmp_path / "d.txt"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        parse_descriptor(path)
    assert where in str(info.value) and words in str(info.value)
    assert "\n" not in str(info.value)


def test_irradiance_variation_at_one_exposure_is_accepted(tmp_path):
    """Method II (§6.3): several bright blocks at one exposure with different photon counts."""
    path = tmp_path / "d.txt"
    path.write_text(HEAD + B1 + "b 1000 20\ni e.tif\ni f.tif\n" + D1)
    assert [b.photons for b in parse_descriptor(path).blocks if not b.dark] == [10, 20]


@settings(max_examples=200, deadline=None)
@given(st.lists(st.text(alphabet="vnbdil 0123456789.,-eaInf#\\/\t", max_size=24), max_size=12))
def test_fuzzed_descriptors_parse_or_refuse_in_one_line(tmp_path_factory, lines):
    path = tmp_path_factory.mktemp("fuzz") / "d.txt"
    path.write_text("\n".join(lines))
    try:
        parse_descriptor(path)
    except ConfigError as exc:
        assert "\n" not in str(exc)


def _images(tmp_path, shape=(8, 8), values=(100, 102)):
    for name, value in zip(("a.tif", "b.tif", "c.tif", "d.tif"), (*values, 10, 11), strict=True):
        tifffile.imwrite(tmp_path / name, np.full(shape, value, np.uint16))


def test_images_are_checked_against_the_n_line(tmp_path):
    path = tmp_path / "d.txt"
    path.write_text(HEAD + B1 + D1)
    _images(tmp_path, shape=(8, 9))
    with pytest.raises(ConfigError, match="differs from the descriptor's n line"):
        photon_transfer_from_descriptor(path)
    _images(tmp_path, values=(100, 5000))
    with pytest.raises(ConfigError, match="outside 0..4095"):
        photon_transfer_from_descriptor(path)
    (tmp_path / "b.tif").unlink()
    with pytest.raises(ConfigError, match="file not found"):
        photon_transfer_from_descriptor(path)


def _sim_transfer():
    truth = SimTruth.from_sensor_profile(
        load_sensor_profile("imx250m"), resolution_px=(64, 64), dark_current_e_per_s=200.0, dsnu_e=1.5, prnu_percent=1.0
    )
    bench = DirectBench(truth, 1.07e5, 0.6, seed=2)
    return bench.photon_transfer(np.linspace(2e3, 115e3, 30), dark_exposures_us=np.linspace(1e5, 6e5, 6))


def test_export_import_round_trip(tmp_path):
    pt = _sim_transfer()
    path = write_descriptor(pt, tmp_path / "desc", shape=(96, 96), seed=1)
    back = photon_transfer_from_descriptor(path)
    np.testing.assert_allclose(back.photons, np.sort(pt.photons), rtol=1e-8)
    np.testing.assert_allclose(back.exposure_s, np.sort(pt.exposure_s), rtol=1e-8)
    assert back.stack is not None and back.stack.bright.frames == 16
    a, b = characterize(pt).values, characterize(back).values
    assert b["K_dn_per_e"] == pytest.approx(a["K_dn_per_e"], rel=0.02)
    assert b["quantum_efficiency"] == pytest.approx(a["quantum_efficiency"], rel=0.02)
    assert b["dark_noise_e"] == pytest.approx(a["dark_noise_e"], rel=0.05)
    # synthetic images do not pile up at a clip level: the variance maximum (one step later) stands in for §6.6
    assert abs(b["saturation_index"] - a["saturation_index"]) <= 1
    assert b["dsnu_e"] == pytest.approx(a["dsnu_e"], rel=0.15)
    assert b["prnu_percent"] == pytest.approx(a["prnu_percent"], rel=0.15)
    assert "SYNTHETIC" in path.read_text()
    with pytest.raises(ConfigError, match="refusing to overwrite"):
        write_descriptor(pt, tmp_path / "desc")


def test_reading_into_a_reused_array_checks_the_same(tmp_path):
    """A TIFF read into the thread's reused array is that array; one of another size or type is read as it is and
    checked as before."""
    path = tmp_path / "d.txt"
    path.write_text(HEAD + B1 + D1)
    desc = parse_descriptor(path)
    reader = ImageReader(tmp_path, desc)
    buffer = np.empty((desc.height, desc.width), np.uint16)
    _images(tmp_path)
    assert reader.read("a.tif", buffer) is buffer and np.all(buffer == 100)
    tifffile.imwrite(tmp_path / "a.tif", np.full((desc.height, desc.width), 7, np.uint8))
    image = reader.read("a.tif", buffer)
    assert image is not buffer and image.dtype == np.uint8 and np.all(image == 7)
    _images(tmp_path, shape=(8, 9))
    with pytest.raises(ConfigError, match="differs from the descriptor's n line"):
        reader.read("a.tif", buffer)


def test_images_laid_out_alike_are_read_as_tifffile_reads_them(tmp_path):
    """After the first TIFF, images with the same layout are read at their pixels without tifffile: each gives its
    own pixels (into the reused array or not); an image of the same size whose header differs (big-endian, another
    description) is read through tifffile as before; one of another layout likewise; out-of-range values are still
    refused."""
    path = tmp_path / "d.txt"
    path.write_text(HEAD + B1 + D1)
    desc = parse_descriptor(path)
    reader = ImageReader(tmp_path, desc)
    rng = np.random.default_rng(3)
    images = {name: rng.integers(0, 4096, (8, 8)).astype(np.uint16) for name in ("a.tif", "b.tif", "c.tif")}
    for name, image in images.items():
        tifffile.imwrite(tmp_path / name, image)
    tifffile.imwrite(tmp_path / "d.tif", images["a.tif"].byteswap().view(">u2"), byteorder=">")
    buffer = np.empty((8, 8), np.uint16)
    assert np.array_equal(reader.read("a.tif", buffer), images["a.tif"])  # tifffile: the layout is learnt
    for name in ("b.tif", "c.tif", "a.tif"):
        assert np.array_equal(reader.read(name, buffer), images[name])
        assert np.array_equal(reader.read(name), images[name])
    assert (tmp_path / "d.tif").stat().st_size == (tmp_path / "a.tif").stat().st_size
    assert np.array_equal(reader.read("d.tif", buffer), images["a.tif"])
    tifffile.imwrite(tmp_path / "c.tif", images["c.tif"], description="x" * 5)
    assert np.array_equal(reader.read("c.tif", buffer), images["c.tif"])
    tifffile.imwrite(tmp_path / "b.tif", np.full((8, 8), 4096, np.uint16))
    with pytest.raises(ConfigError, match="outside 0..4095"):
        reader.read("b.tif", buffer)
