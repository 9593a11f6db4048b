"""The one saturation rule of uwlab: when a recorded pixel, frame or point is saturated.

A pixel is saturated when its code reaches the camera's *clip level*, the highest code the camera delivers. That
is often below the ADC's maximum 2^k − 1: at low gain many sensors clip at their full well first, at
μ_y = μ_y,dark + K μ_e,full. EMVA 1288 Release 4.0 Linear, §6.6 ("Saturation") asks for the same first step:
"it is first required to find the maximum possible value y ... for some sensors, this may be a smaller value"
than 2^k − 1. The clip level comes from, in this order:

1. ``profile``: the sensor profile — saturation capacity μ_e,sat, system gain K at the current gain, dark offset
   and black level, at the profile's bit depth, shifted to the output format (`sensor_clip_dn`);
2. ``detected``: the data — the frame's maximum code when the pixels pile up there (`detect_clip_dn`): it holds
   at least `PILEUP_MIN_FRACTION` of the pixels (and `PILEUP_MIN_PIXELS`), at least `PILEUP_RATIO` times as many
   as the next lower code present (an unclipped distribution thins out towards its maximum, a clipped one piles
   up), and it lies in the upper part of the range (≥ `PILEUP_MIN_RANGE_FRACTION` of the ADC maximum; no sensor
   clips lower). A pile-up below the profile's level wins over the profile: the camera clips earlier than its
   profile says;
3. ``adc``: the ADC maximum of the output format (`adc_max_dn`; for an MSB-aligned ADC of fewer bits than the
   format, its top code).

A frame's saturated fraction is the fraction of its pixels at or above the clip level; a point's is the fraction
of ROI pixels that reach it in any of the point's frames (`uwlab.experiments.frames.stack`). A point is saturated
when that fraction exceeds `POINT_SATURATED_FRACTION` = 0.2 %: Release 4.0 §6.6 sets the saturation exposure
where "between 0.1 – 0.2 % of the total number of pixels show the maximum value", the most a mean and a variance
tolerate unbiased (< 0.37 % variance bias for a normal distribution).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uwlab.drivers.camera.pixels import pixel_format

POINT_SATURATED_FRACTION = 0.002
PILEUP_MIN_FRACTION = 1e-4
PILEUP_MIN_PIXELS = 4
PILEUP_RATIO = 2.0
PILEUP_MIN_RANGE_FRACTION = 0.25
SOURCES = ("profile", "detected", "adc")


@dataclass(frozen=True)
class ClipLevel:
    """Codes at or above ``dn`` are saturated; ``source`` says where the level came from (`SOURCES`)."""

    dn: float
    source: str

    def fraction(self, image: np.ndarray) -> float:
        """Fraction of the pixels of ``image`` at or above the clip level."""
        image = np.asarray(image)
        return float(np.count_nonzero(image >= self.dn)) / image.size if image.size else 0.0


def adc_max_dn(format_name: str, native_bits: int | None = None) -> float:
    """The top code of the output format: 2^bits − 1, or the top code of a ``native_bits`` ADC whose data are
    MSB-aligned in a wider format (a 12-bit ADC in Mono16 tops out at 0xFFF0)."""
    fmt = pixel_format(format_name)
    if native_bits is None or native_bits >= fmt.bits:
        return float(fmt.max_value)
    return float(((1 << native_bits) - 1) << (fmt.bits - native_bits))


def sensor_clip_dn(
    k_dn_per_e: float, saturation_e: float, offset_dn: float, native_bits: int, format_name: str
) -> float:
    """The code of a pixel at the sensor's saturation capacity: K μ_e,sat + offset at the native bit depth
    (K at the current gain; offset = dark offset + black level), rounded, capped at the ADC maximum, and shifted to
    the output format as cameras do (left for wider formats, right for narrower).

    >>> sensor_clip_dn(0.35, 10500, 16.0, 12, "Mono16")
    59056.0
    """
    fmt = pixel_format(format_name)
    native = min(int(np.floor(k_dn_per_e * saturation_e + offset_dn + 0.5)), (1 << native_bits) - 1)
    shift = fmt.bits - native_bits
    return float(native << shift if shift >= 0 else native >> -shift)


def detect_clip_dn(image: np.ndarray, adc_max: float) -> float | None:
    """The frame's maximum code when the pixels pile up there (see the module docstring), else None."""
    values = np.asarray(image).ravel()
    if values.size == 0:
        return None
    top = values.max()
    if top < PILEUP_MIN_RANGE_FRACTION * adc_max:
        return None
    at_top = int(np.count_nonzero(values == top))
    if at_top < max(PILEUP_MIN_PIXELS, PILEUP_MIN_FRACTION * values.size):
        return None
    below = values[values < top]
    next_count = int(np.count_nonzero(below == below.max())) if below.size else 0
    return float(top) if at_top >= PILEUP_RATIO * next_count else None


def clip_level(
    format_name: str,
    *,
    native_bits: int | None = None,
    profile_dn: float | None = None,
    image: np.ndarray | None = None,
) -> ClipLevel:
    """The clip level of a camera delivering ``format_name`` (see the module docstring for the order)."""
    adc = adc_max_dn(format_name, native_bits)
    detected = detect_clip_dn(image, adc) if image is not None else None
    if profile_dn is not None and (detected is None or detected >= profile_dn):
        return ClipLevel(min(float(profile_dn), adc), "profile")
    if detected is not None:
        return ClipLevel(detected, "detected")
    return ClipLevel(adc, "adc")


def point_saturated(saturated_fraction: float, threshold: float = POINT_SATURATED_FRACTION) -> bool:
    """A point is saturated when more than ``threshold`` of its ROI pixels reach the clip level."""
    return bool(saturated_fraction > threshold)
