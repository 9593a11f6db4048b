"""The slanted-edge MTF (ISO 12233 e-SFR) against edges whose MTF is known in closed form: a Gaussian blur
(exp(−2π²σ²f²)), a uniform defocus disk (2·J1(2πRf)/(2πRf)) and a square pixel's aperture seen across an edge at θ
(sinc(f cos θ)·sinc(f sin θ)); at several angles, with noise, per Bayer channel, and the refusals."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import erf, j1

from uwlab.drivers.camera.pixels import bayer_sites
from uwlab.errors import ConfigError
from uwlab.experiments.frames.esfr import find_edges, slanted_edge, slanted_edges

DARK, STEP = 100.0, 800.0


def distance(shape, angle_deg, centre=None):
    """Signed distance (px) of each pixel centre from a line through ``centre`` tilted ``angle_deg`` from the
    columns; positive on the bright side."""
    rows, cols = shape
    cy, cx = centre if centre is not None else (rows / 2.0, cols / 2.0)
    y, x = np.mgrid[0:rows, 0:cols]
    t = np.radians(angle_deg)
    return ((x - cx) - np.tan(t) * (y - cy)) * np.cos(t)


def gaussian_edge(shape, angle_deg, sigma_px):
    return DARK + STEP * 0.5 * (1 + erf(distance(shape, angle_deg) / (sigma_px * np.sqrt(2))))


def gaussian_mtf50(sigma_px):
    return np.sqrt(np.log(2) / 2) / (np.pi * sigma_px)


def noisy(image, snr, seed):
    return image + np.random.default_rng(seed).normal(0.0, STEP / snr, image.shape)


@pytest.mark.parametrize("angle_deg", [3.0, 5.0, 10.0, 15.0])
@pytest.mark.parametrize("sigma_px", [0.5, 1.0, 2.0, 3.0])
def test_gaussian_edges_with_noise_give_mtf50_within_2_percent(angle_deg, sigma_px):
    image = noisy(gaussian_edge((400, 256), angle_deg, sigma_px), snr=50, seed=int(10 * sigma_px + angle_deg))
    edge = slanted_edge(image)
    assert edge.angle_deg == pytest.approx(angle_deg, abs=0.1)
    assert edge.mtf50_cy_per_px == pytest.approx(gaussian_mtf50(sigma_px), rel=0.02)


@pytest.mark.parametrize("sigma_px", [0.5, 1.5])
def test_the_whole_curve_follows_the_gaussian_closed_form(sigma_px):
    edge = slanted_edge(gaussian_edge((200, 128), 5.0, sigma_px))
    f = edge.frequency_cy_per_px
    truth = np.exp(-2 * np.pi**2 * sigma_px**2 * f**2)
    band = f <= 0.5
    assert np.max(np.abs(edge.mtf[band] - truth[band])) < 0.01
    assert edge.mtf_nyquist == pytest.approx(np.exp(-2 * np.pi**2 * sigma_px**2 * 0.25), abs=0.01)


@pytest.mark.parametrize("radius_px", [1.5, 3.0])
def test_a_defocus_disk_gives_the_airy_free_closed_form(radius_px):
    """A uniform blur disk of radius R: the edge's profile is the disk's area beyond the line, its MTF
    2·J1(2πRf)/(2πRf), whose first 0.5 is at 2πRf = 2.2153."""
    d = np.clip(distance((300, 200), 7.0) / radius_px, -1, 1)
    fraction = 1 - (np.arccos(d) - d * np.sqrt(1 - d**2)) / np.pi
    edge = slanted_edge(DARK + STEP * fraction)
    z50 = brentq(lambda z: 2 * j1(z) / z - 0.5, 1.0, 3.0)
    assert edge.mtf50_cy_per_px == pytest.approx(z50 / (2 * np.pi * radius_px), rel=0.02)


@pytest.mark.parametrize("angle_deg", [4.0, 12.0])
def test_a_sharp_edge_through_square_pixels_gives_the_pixel_aperture(angle_deg):
    """A step edge integrated over each square pixel (16 × 16 sub-samples): MTF = sinc(f cos θ)·sinc(f sin θ)."""
    sub = 16
    rows, cols = 160, 128
    fine = distance((rows * sub, cols * sub), angle_deg, centre=(rows * sub / 2.0, cols * sub / 2.0)) > 0
    image = DARK + STEP * fine.reshape(rows, sub, cols, sub).mean(axis=(1, 3))
    edge = slanted_edge(image)
    t = np.radians(angle_deg)
    truth = brentq(lambda f: np.sinc(f * np.cos(t)) * np.sinc(f * np.sin(t)) - 0.5, 0.1, 0.9)
    assert edge.mtf50_cy_per_px == pytest.approx(truth, rel=0.02)
    f = edge.frequency_cy_per_px
    expected = np.abs(np.sinc(f * np.cos(t)) * np.sinc(f * np.sin(t)))
    assert np.max(np.abs(edge.mtf - expected)[f <= 0.5]) < 0.02


def test_orientation_and_polarity_do_not_change_the_result():
    image = gaussian_edge((200, 128), 6.0, 1.2)
    reference = slanted_edge(image).mtf50_cy_per_px
    for variant, orientation in ((image[:, ::-1], "vertical"), (image.T, "horizontal"), (image.T[::-1], "horizontal")):
        edge = slanted_edge(np.ascontiguousarray(variant))
        assert edge.orientation == orientation
        assert abs(edge.angle_deg) == pytest.approx(6.0, abs=0.05)
        assert edge.mtf50_cy_per_px == pytest.approx(reference, rel=0.005)


@pytest.mark.parametrize("layout", ["RG", "GB"])
def test_each_bayer_channel_is_measured_on_its_own_sites(layout):
    """A mosaic whose channels are blurred differently (σ 0.8, 1.3, 2.0 px, as a lens's lateral colour would):
    each channel, measured on its own sites, gives its own closed form on the sensor's frequency axis."""
    shape = (480, 256)
    sigmas = {"R": 0.8, "G": 1.3, "B": 2.0}
    mosaic = np.zeros(shape)
    for colour, cells in bayer_sites(layout).items():
        plane = gaussian_edge(shape, 8.0, sigmas[colour])
        for r, c in cells:
            mosaic[r::2, c::2] = plane[r::2, c::2]
    for colour, sigma in sigmas.items():
        edge = slanted_edge(mosaic, sites=bayer_sites(layout)[colour])
        assert edge.mtf50_cy_per_px == pytest.approx(gaussian_mtf50(sigma), rel=0.02), colour
    # An ROI starting at an odd pixel shifts the mosaic's phase: the sites follow it.
    edge = slanted_edge(mosaic, roi=(1, 1, 255, 479), sites=bayer_sites(layout)["R"])
    assert edge.mtf50_cy_per_px == pytest.approx(gaussian_mtf50(sigmas["R"]), rel=0.02)


def test_every_edge_of_a_chart_is_found_and_measured():
    """A dark square tilted 5° on a bright board: four edges, two each way, all giving the blur's MTF50."""
    rows = cols = 400
    y, x = np.mgrid[0:rows, 0:cols]
    t = np.radians(5.0)
    u = (x - 200) * np.cos(t) + (y - 200) * np.sin(t)
    v = -(x - 200) * np.sin(t) + (y - 200) * np.cos(t)
    inside = np.maximum(np.abs(u), np.abs(v)) - 100  # signed distance (px) outside the square's edges
    image = DARK + STEP * 0.5 * (1 + erf(inside / (1.0 * np.sqrt(2))))
    edges = slanted_edges(image)
    assert len(edges) == 4 and len(find_edges(image)) == 4
    assert sorted(e.orientation for e in edges) == ["horizontal", "horizontal", "vertical", "vertical"]
    for edge in edges:
        assert abs(edge.angle_deg) == pytest.approx(5.0, abs=0.2)
        assert edge.mtf50_cy_per_px == pytest.approx(gaussian_mtf50(1.0), rel=0.03)


def test_refusals_name_the_problem():
    flat = noisy(np.full((100, 100), 400.0), snr=50, seed=1)
    with pytest.raises(ConfigError, match="no edge"):
        slanted_edge(flat)
    with pytest.raises(ConfigError, match="from the pixel grid"):
        slanted_edge(gaussian_edge((200, 128), 1.0, 1.0))
    clipped = np.clip(gaussian_edge((200, 128), 5.0, 1.0) * 0.4, 0, 255).astype(np.uint8)  # bright side at 360 → 255
    with pytest.raises(ConfigError, match="saturated"):
        slanted_edge(clipped)
    with pytest.raises(ConfigError, match="no straight slanted edge|no measurable edge"):
        slanted_edges(flat)
