"""A slanted-edge chart in the simulated tank, rendered sharp or blurred by ray sampling (not by the model's MTF).

The chart is a black-and-white straight edge on the board, tilted from the pixel columns (ISO 12233's slanted
edge), seen by the camera through the tank's flat wall. Every pixel's value is the mean, over Monte Carlo samples,
of where the light of the chart's points lands on the sensor; the blur comes from four independent random
displacements, each drawn from its own physics in the spatial domain (`uwlab.model.mtf` predicts the same chain from
closed-form transfer functions in the frequency domain: the two meet only in the validation):

- Defocus, by ray tracing: the board's on-axis point is traced paraxially through water, the acrylic wall and the
  air gap (Snell's law at each face, a ray of 10⁻⁴ rad) and its apparent position found where the air ray's
  extension meets the axis; a thin lens (f, N) in air images it at b = 1/(1/f − 1/v); the sensor sits where the
  lens focus setting v_f images, b_f = 1/(1/f − 1/v_f). A ray through a point a of the entrance pupil (uniform
  over the disk of diameter f/N) lands at a·(1 − b_f/b) from the image point.
- Diffraction: a displacement drawn from the Airy pattern of the circular pupil, its radius by inverting the
  encircled energy 1 − J₀²(x) − J₁²(x), x = π r/(λN) (Born & Wolf, *Principles of Optics*, 7th ed., §8.5.2).
- Motion: the board moves at the vehicle speed during the exposure; a uniform time in [0, t_exp] places it; the
  image moves by the lateral magnification b/v (a flat interface leaves lateral sizes unchanged, paraxially).
- The pixel: each pixel averages the chart over an 8 × 8 grid of points across its area (100 % fill factor).

On the simulated rig (`chart_rate_map`, a geometry sweep of ``uwlab sweep --sim``) the chart is a patch of
`CHART_SIZE_PX` pixels square at the sensor's centre, on the board: its white is the board's electron rate there,
its black `CHART_BLACK` of it; the patch keeps its size in pixels whatever the target's distance, and its
illumination is the board's (a simplification: only the blur follows the distance). The simulated camera then adds
its own noise (`uwlab.sim.devices.camera.SimSensor`).

Electrons (`render_edge`): the dark and bright sides give ``dark_e`` and ``bright_e``; Poisson shot noise,
Gaussian read noise (``dark_noise_e``), then DN = K · e + offset, rounded and clipped to the bit depth (EMVA 1288's
linear model).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy.special import j0, j1

CHART_SIZE_PX = 192  # the simulated rig's chart patch, pixels a side
CHART_BLACK = 0.1  # the chart's black against its white (a printed matte black is 4-10 % reflective; assumed)
SUBPIXELS = 8  # per pixel side: the pixel aperture's sampling
PSF_SAMPLES = 400_000  # Monte Carlo displacements per image (the ESF's error ≲ 1e-3)
PARAXIAL_RAD = 1e-4  # the ray traced for the wall's apparent distance


@dataclass(frozen=True)
class TankOptics:
    """The camera and the wall between it and the chart: thin lens ``focal_length_m`` at ``f_number``; square
    pixels of ``pixel_pitch_m``; the wall's outer face ``camera_gap_m`` from the pupil, ``wall_thickness_m`` of
    index ``wall_index``, water of ``water_index``; diffraction at ``wavelength_m``."""

    focal_length_m: float
    f_number: float
    pixel_pitch_m: float
    camera_gap_m: float
    wall_thickness_m: float
    wall_index: float
    water_index: float
    wavelength_m: float = 550e-9

    def apparent_distance_m(self, target_distance_m: float) -> float:
        """Where a point ``target_distance_m`` from the pupil appears from the air (paraxial ray trace)."""
        depth = target_distance_m - self.camera_gap_m - self.wall_thickness_m
        sin_w = np.sin(PARAXIAL_RAD)
        lateral = depth * np.tan(PARAXIAL_RAD)
        sin_p = self.water_index * sin_w / self.wall_index
        lateral += self.wall_thickness_m * sin_p / np.sqrt(1 - sin_p**2)
        sin_a = self.water_index * sin_w
        tan_a = sin_a / np.sqrt(1 - sin_a**2)
        lateral += self.camera_gap_m * tan_a
        return float(lateral / tan_a)

    def image_distance_m(self, apparent_m: float) -> float:
        return 1.0 / (1.0 / self.focal_length_m - 1.0 / apparent_m)


@functools.cache
def _encircled_energy() -> tuple[np.ndarray, np.ndarray]:
    """The Airy pattern's encircled energy 1 − J₀²(x) − J₁²(x) on x = π r/(λN) out to 60 dark rings (normalised)."""
    x = np.linspace(0.0, 200.0, 200_001)
    energy = 1.0 - j0(x) ** 2 - j1(x) ** 2
    return x, np.maximum.accumulate(energy) / energy[-1]


def _airy_radii(rng: np.random.Generator, n: int, wavelength_m: float, f_number: float) -> np.ndarray:
    """Radii (m) drawn from the Airy pattern by inverting its encircled energy."""
    x, energy = _encircled_energy()
    return np.interp(rng.random(n), energy, x) * wavelength_m * f_number / np.pi


def normal_displacements_px(
    optics: TankOptics,
    target_distance_m: float,
    focus_setting_m: float,
    edge_normal: np.ndarray,
    rng: np.random.Generator,
    speed_m_s: float = 0.0,
    exposure_s: float = 0.0,
    motion_direction: np.ndarray | None = None,
    samples: int = PSF_SAMPLES,
) -> np.ndarray:
    """Samples of the image's displacement (pixels) along ``edge_normal`` (a unit 2-vector on the sensor): defocus,
    diffraction and motion (module docstring)."""
    v = optics.apparent_distance_m(target_distance_m)
    b = optics.image_distance_m(v)
    b_f = optics.image_distance_m(focus_setting_m)
    pupil_radius = optics.focal_length_m / optics.f_number / 2.0
    r = pupil_radius * np.sqrt(rng.random(samples))
    phi = 2 * np.pi * rng.random(samples)
    shift = (1.0 - b_f / b) * np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)
    airy = _airy_radii(rng, samples, optics.wavelength_m, optics.f_number)
    psi = 2 * np.pi * rng.random(samples)
    shift += np.stack([airy * np.cos(psi), airy * np.sin(psi)], axis=1)
    if speed_m_s > 0 and exposure_s > 0:
        direction = np.array([1.0, 0.0]) if motion_direction is None else np.asarray(motion_direction, float)
        travel = speed_m_s * exposure_s * rng.random(samples) * (b / v)
        shift += travel[:, None] * direction[None, :]
    return shift @ np.asarray(edge_normal, float) / optics.pixel_pitch_m


def edge_fraction(
    optics: TankOptics,
    target_distance_m: float,
    focus_setting_m: float,
    rng: np.random.Generator,
    *,
    shape_yx: tuple[int, int] = (240, 160),
    angle_deg: float = 5.0,
    speed_m_s: float = 0.0,
    exposure_s: float = 0.0,
) -> np.ndarray:
    """The fraction of the chart's white each pixel of a ``shape_yx`` region sees (float64, 0 on the black side, 1 on
    the white): a vertical edge tilted ``angle_deg``, dark on the left, through the region's centre, blurred by the
    displacements of `normal_displacements_px` and integrated over each pixel (module docstring)."""
    t = np.radians(angle_deg)
    normal = np.array([np.cos(t), -np.sin(t)])  # sensor (x, y): distance d = (x − x_c) cos t − (y − y_c) sin t
    displacement = np.sort(
        normal_displacements_px(optics, target_distance_m, focus_setting_m, normal, rng, speed_m_s, exposure_s)
    )
    rows, cols = shape_yx
    offsets = (np.arange(SUBPIXELS) + 0.5) / SUBPIXELS - 0.5
    y = np.arange(rows)[:, None, None, None] + offsets[None, None, :, None]
    x = np.arange(cols)[None, :, None, None] + offsets[None, None, None, :]
    d = (x - cols / 2.0) * normal[0] + (y - rows / 2.0) * normal[1]
    # The chart is bright where d + X > 0 for the point that lands here: the fraction of samples with X > −d,
    # tabulated on a fine grid of d (1/64 px) and interpolated at each sub-pixel point.
    grid = np.arange(d.min() - 1.0, d.max() + 1.0, 1.0 / 64)
    edge_spread = 1.0 - np.searchsorted(displacement, -grid, side="right") / displacement.size
    return np.interp(d, grid, edge_spread).reshape(rows, cols, SUBPIXELS * SUBPIXELS).mean(axis=2)


def render_edge(
    optics: TankOptics,
    target_distance_m: float,
    focus_setting_m: float,
    *,
    shape_yx: tuple[int, int] = (240, 160),
    angle_deg: float = 5.0,
    dark_e: float = 800.0,
    bright_e: float = 8000.0,
    k_dn_per_e: float = 0.35,
    dark_noise_e: float = 2.5,
    offset_dn: float = 20.0,
    bit_depth: int = 12,
    speed_m_s: float = 0.0,
    exposure_s: float = 0.0,
    seed: int = 0,
) -> np.ndarray:
    """A raw image (uint16 DN) of a vertical edge tilted ``angle_deg``, dark on the left, centred in the frame
    (`edge_fraction`); see the module docstring for the blur and noise."""
    rng = np.random.default_rng(seed)
    fraction = edge_fraction(
        optics,
        target_distance_m,
        focus_setting_m,
        rng,
        shape_yx=shape_yx,
        angle_deg=angle_deg,
        speed_m_s=speed_m_s,
        exposure_s=exposure_s,
    )
    electrons = rng.poisson(dark_e + (bright_e - dark_e) * fraction).astype(np.float64)
    electrons += rng.normal(0.0, dark_noise_e, electrons.shape)
    dn = np.round(offset_dn + k_dn_per_e * electrons)
    return np.clip(dn, 0, 2**bit_depth - 1).astype(np.uint16)


def rig_optics(design, world, tank: bool, f_number: float) -> TankOptics:
    """The camera and port of a simulated rig for the chart: the sweep's lens (``design``, at ``f_number``) and
    sensor; the tank's wall as the world (``world``, `uwlab.sim.world.WorldSettings`) renders it when ``tank``, else
    the design's flat port. `ValueError` for a dome port or a bare sensor (the chart needs a lens and a flat port)."""
    focal_mm = design["lens.focal_length_mm"]
    if focal_mm is None:
        raise ValueError("the simulated chart needs a lens")
    if tank:
        gap, thickness, index = world.camera_gap_m, world.wall_thickness_m, world.wall_index
    elif design["housing.port"] == "flat":
        gap, thickness = design["housing.flat_air_gap_mm"] * 1e-3, design["housing.flat_thickness_mm"] * 1e-3
        index = design["housing.port_index"]
    else:
        raise ValueError("the simulated chart is rendered through a flat port only")
    return TankOptics(
        focal_length_m=float(focal_mm) * 1e-3,
        f_number=float(f_number),
        pixel_pitch_m=design.sensor.pixel_size_um * 1e-6,
        camera_gap_m=float(gap),
        wall_thickness_m=float(thickness),
        wall_index=float(index),
        water_index=float(design["housing.water_index"]),
    )


def chart_rate_map(
    rate_e_per_s: np.ndarray,
    optics: TankOptics,
    target_distance_m: float,
    focus_setting_m: float,
    seed: int | tuple[int, ...],
    *,
    angle_deg: float = 5.0,
    speed_m_s: float = 0.0,
    exposure_s: float = 0.0,
    size_px: int = CHART_SIZE_PX,
    black: float = CHART_BLACK,
) -> np.ndarray:
    """A copy of the full sensor's electron-rate map with the chart's patch at its centre (module docstring): its
    white the map's rate, its black ``black`` of it, the edge blurred by `edge_fraction`."""
    out = np.array(rate_e_per_s, dtype=np.float32, copy=True)
    height, width = out.shape
    rows, cols = min(size_px, height), min(size_px, width)
    y0, x0 = (height - rows) // 2, (width - cols) // 2
    fraction = edge_fraction(
        optics,
        target_distance_m,
        focus_setting_m,
        np.random.default_rng(seed),
        shape_yx=(rows, cols),
        angle_deg=angle_deg,
        speed_m_s=speed_m_s,
        exposure_s=exposure_s,
    )
    patch = out[y0 : y0 + rows, x0 : x0 + cols]
    patch *= (black + (1.0 - black) * fraction).astype(np.float32)
    return out
