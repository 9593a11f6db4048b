"""The modulation transfer function a camera system should have: defocus through the port, diffraction, the pixel
aperture and motion blur, as a slanted edge measures it (`uwlab.experiments.frames.esfr`).

Conventions: frequencies in cycles per pixel on the sensor (Nyquist 0.5), along the normal of the edge measured;
lengths in metres; the lens is a thin lens in air behind the port, so distances in water enter through the image
the port forms of them (`uwlab.model.focus.target_image_distance_m`: a flat port's apparent distance, a dome's
virtual image), as the depth of field of `uwlab.model.optics` does. The MTF of a chain is the product of its
stages' (linear, shift-invariant stages in series).

- Defocus (geometrical optics): a lens of focal length f and f-number N focused at the air-equivalent distance
  v_f images a point at v into a uniform disk of diameter c = f² |v − v_f| / (N v (v_f − f)) on the sensor — the
  relation whose c = coc gives `uwlab.model.optics.dof_in_air`'s limits. A uniform disk of diameter c has the
  MTF 2 J₁(π c ν) / (π c ν) at ν cycles per metre (Goodman, *Introduction to Fourier Optics*, 3rd ed., 2005,
  §6.4.1, the "geometrical-optics" defocused OTF; its first zero, where contrast reverses, at ν = 1.22 / c).
- Diffraction of the circular aperture (incoherent, aberration-free): with the cut-off ν_c = 1 / (λ N),
  MTF = (2/π) [arccos(ν/ν_c) − (ν/ν_c) √(1 − (ν/ν_c)²)] for ν < ν_c, else 0 (Goodman §6.3.2). λ defaults to
  550 nm, the photopic peak.
- Combining defocus and diffraction by a product is the usual approximation (exact for either alone; within a
  few per cent of Hopkins' (1955) defocused OTF once the defocus exceeds about one wave; near focus the diffraction
  term dominates both).
- Pixel aperture: a square pixel of 100 % fill factor integrates over its area; across an edge at angle θ from a
  pixel axis its MTF is sinc(ν_px cos θ) · sinc(ν_px sin θ), sinc(x) = sin(πx)/(πx) (Boreman, *Modulation Transfer
  Function in Optical and Electro-Optical Systems*, SPIE TT52, 2001, §2.2).
- Motion: the image moving uniformly by L pixels during the exposure along a direction at angle φ from the edge
  normal is a box of length L cos φ across the edge: MTF = |sinc(ν_px L cos φ)| (Boreman §2.4). L = speed ·
  exposure / ground sampling distance, the blur of `uwlab.model.evaluation`'s `max_exposure_s`.

>>> round(float(mtf50_cy_per_px(pixel_pitch_m=3.45e-6, blur_diameter_m=0.0, f_number=4.0)), 3)
0.41
"""

from __future__ import annotations

import numpy as np
from scipy.special import j1

WAVELENGTH_M = 550e-9  # the photopic peak: the default wavelength of the diffraction term
FREQUENCIES_CY_PER_PX = np.linspace(0.0, 1.0, 2001)  # where MTF50 is searched (steps of 0.0005 cy/px)


def defocus_blur_diameter_m(image_distance_m, focus_distance_m, focal_length_m, f_number):
    """Diameter [m] on the sensor of the blur disk of a point whose (air-equivalent) image distance is
    ``image_distance_m`` when the lens is focused at ``focus_distance_m`` (module docstring).

    >>> round(float(defocus_blur_diameter_m(0.5, 0.5, 0.012, 4.0)), 12)
    0.0
    """
    v = np.asarray(image_distance_m, float)
    v_f = np.asarray(focus_distance_m, float)
    f = np.asarray(focal_length_m, float)
    return f**2 * np.abs(v - v_f) / (np.asarray(f_number, float) * v * (v_f - f))


def _sinc(x):
    return np.sinc(np.asarray(x, float))


def defocus_mtf(frequency_cy_per_m, blur_diameter_m):
    """MTF of a uniform blur disk of ``blur_diameter_m`` (module docstring); 1 where the diameter is 0."""
    x = np.pi * np.asarray(blur_diameter_m, float) * np.asarray(frequency_cy_per_m, float)
    safe = np.where(np.abs(x) < 1e-9, 1.0, x)
    return np.where(np.abs(x) < 1e-9, 1.0, 2.0 * j1(safe) / safe)


def diffraction_mtf(frequency_cy_per_m, f_number, wavelength_m=WAVELENGTH_M):
    """The diffraction-limited MTF of a circular aperture at ``f_number`` (module docstring)."""
    nu = np.clip(
        np.asarray(frequency_cy_per_m, float) * np.asarray(wavelength_m, float) * np.asarray(f_number, float), 0, 1
    )
    return (2.0 / np.pi) * (np.arccos(nu) - nu * np.sqrt(1.0 - nu**2))


def pixel_mtf(frequency_cy_per_px, edge_angle_rad=0.0):
    """A square pixel's aperture seen across an edge at ``edge_angle_rad`` from a pixel axis (module docstring)."""
    f = np.asarray(frequency_cy_per_px, float)
    return _sinc(f * np.cos(edge_angle_rad)) * _sinc(f * np.sin(edge_angle_rad))


def motion_mtf(frequency_cy_per_px, motion_px, motion_angle_rad=0.0):
    """Uniform motion of ``motion_px`` pixels during the exposure, at ``motion_angle_rad`` from the edge normal."""
    return np.abs(
        _sinc(np.asarray(frequency_cy_per_px, float) * np.asarray(motion_px, float) * np.cos(motion_angle_rad))
    )


def system_mtf(
    frequency_cy_per_px,
    *,
    pixel_pitch_m,
    blur_diameter_m,
    f_number,
    wavelength_m=WAVELENGTH_M,
    edge_angle_rad=0.0,
    motion_px=0.0,
    motion_angle_rad=0.0,
):
    """The product of the four stages (module docstring) at ``frequency_cy_per_px``; every argument broadcasts."""
    f_px = np.asarray(frequency_cy_per_px, float)
    f_m = f_px / np.asarray(pixel_pitch_m, float)
    return (
        defocus_mtf(f_m, blur_diameter_m)
        * diffraction_mtf(f_m, f_number, wavelength_m)
        * pixel_mtf(f_px, edge_angle_rad)
        * motion_mtf(f_px, motion_px, motion_angle_rad)
    )


def mtf50_cy_per_px(**stages):
    """The lowest frequency (cy/px) where `system_mtf` falls to 0.5, by linear interpolation on
    `FREQUENCIES_CY_PER_PX`; NaN where it stays above 0.5 up to 1 cy/px. ``stages``: `system_mtf`'s keywords,
    arrays broadcasting to the shape of the result."""
    shape = np.broadcast_shapes(*(np.shape(v) for v in stages.values()))
    expanded = {k: np.asarray(v, float)[..., None] for k, v in stages.items()}
    f = FREQUENCIES_CY_PER_PX
    curve = system_mtf(np.broadcast_to(f, (*shape, f.size)), **expanded)
    below = curve < 0.5
    first = np.argmax(below, axis=-1)
    found = below.any(axis=-1) & (first > 0)
    i = np.where(found, first, 1)
    m0 = np.take_along_axis(curve, (i - 1)[..., None], -1)[..., 0]
    m1 = np.take_along_axis(curve, i[..., None], -1)[..., 0]
    f0, f1 = f[i - 1], f[i]
    return np.where(found, f0 + (m0 - 0.5) * (f1 - f0) / (m0 - m1), np.nan)


def design_mtf50(d, *, focus_setting_m=None, edge_angle_deg=5.0, motion_angle_deg=0.0, wavelength_m=WAVELENGTH_M):
    """MTF50 (cy/px) of a design's camera imaging a slanted edge at its target distance (`operation.altitude_m`),
    the lens focused at ``focus_setting_m`` (the distance set on the lens, air-equivalent, from the pupil; default:
    on the target's image, `uwlab.model.focus.target_image_distance_m`), the edge at ``edge_angle_deg`` from the
    pixel columns, the vehicle moving at ``operation.speed_m_s`` during ``operation.exposure_s`` at
    ``motion_angle_deg`` from the edge normal. Broadcasts over the design's grid axes; NaN for a bare sensor."""
    from uwlab.model import focus
    from uwlab.model.chain import effective_focal_length_m, port_geometry

    op = d.values["operation"]
    focal_mm = d["lens.focal_length_mm"]
    if focal_mm is None:
        return np.nan
    f_m = np.asarray(focal_mm, float) * 1e-3
    port, n_w, flat, dome, decenter_z = port_geometry(d)
    image = focus.target_image_distance_m(op["altitude_m"], port, n_w, flat, dome, decenter_z)
    focused = image if focus_setting_m is None else np.asarray(focus_setting_m, float)
    sensor = d.sensor
    pitch_m = sensor.pixel_size_um * 1e-6
    exposure = op["exposure_s"]
    motion_px = 0.0
    if not isinstance(exposure, str):
        # Ground sampling distance at the target: the pixel pitch scaled by distance over the focal length in water.
        gsd_m = pitch_m * np.asarray(op["altitude_m"], float) / effective_focal_length_m(d)
        motion_px = np.asarray(op["speed_m_s"], float) * np.asarray(exposure, float) / gsd_m
    return mtf50_cy_per_px(
        pixel_pitch_m=pitch_m,
        blur_diameter_m=defocus_blur_diameter_m(image, focused, f_m, d["lens.f_number"]),
        f_number=d["lens.f_number"],
        wavelength_m=wavelength_m,
        edge_angle_rad=np.radians(edge_angle_deg),
        motion_px=motion_px,
        motion_angle_rad=np.radians(motion_angle_deg),
    )
