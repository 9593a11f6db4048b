"""Statistics of one frame (what ``uwlab grab`` reports), per colour channel for a raw Bayer image.

A Bayer frame is kept as the raw mosaic: each pixel is one filter's measurement, so a channel's statistics are over
its own sites only, no demosaicing (EMVA 1288 Release 4.0 Linear, §1.2 and §4: each colour channel of a colour
camera is treated as its own sensor). ``G`` pools both green sites of the 2 × 2 cell. Saturated pixels follow the
one rule of `uwlab.experiments.saturation`: one clip level per frame (the camera clips every channel at the same
code), a channel's saturated fraction is the fraction of its sites at or above it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from uwlab.drivers.camera.pixels import bayer_sites
from uwlab.experiments.saturation import frame_clip_level

if TYPE_CHECKING:  # annotations only
    from uwlab.drivers.camera import Frame
    from uwlab.model.sensor import SensorProfile

CHANNELS = ("R", "G", "B")
# Each mosaic colour's name as the design model's ``sensor.channel`` and a colour profile's QE column call it.
CHANNEL_NAMES = {"R": "red", "G": "green", "B": "blue"}


def channel_pixels(image: np.ndarray, layout: str, x0: int = 0, y0: int = 0) -> dict[str, np.ndarray]:
    """The pixels of each colour of a Bayer mosaic of ``layout`` (1-D arrays; ``G`` both green sites), for an
    ``image`` cropped from the mosaic at (x0, y0) (odd offsets shift the phase).

    >>> mosaic = np.array([[1, 2], [3, 4]])
    >>> {c: v.tolist() for c, v in channel_pixels(mosaic, "RG").items()}
    {'R': [1], 'G': [2, 3], 'B': [4]}
    """
    return {
        colour: np.concatenate([image[row::2, col::2].ravel() for row, col in cells])
        for colour, cells in bayer_sites(layout, x0, y0).items()
    }


def frame_statistics(frame: Frame, sensor: SensorProfile | None = None) -> dict:
    """One frame's identity, settings and statistics: mean, std, min, max, saturated fraction and the clip level
    with its source; ``channels`` (``{"R"|"G"|"B": {"mean", "saturated_fraction"}}``) for a Bayer frame, else
    None."""
    img, settings = frame.image, frame.settings
    clip = frame_clip_level(frame, sensor)
    channels = None
    if frame.bayer is not None:
        channels = {
            colour: {"mean": float(values.mean()), "saturated_fraction": clip.fraction(values)}
            for colour, values in channel_pixels(img, frame.bayer).items()
        }
    return {
        "frame_id": frame.frame_id,
        "timestamp_ns": frame.timestamp_ns,
        "width": int(img.shape[1]),
        "height": int(img.shape[0]),
        "pixel_format": frame.pixel_format,
        "bayer": frame.bayer,
        "exposure_us": settings.exposure_us,
        "gain_db": settings.gain_db,
        "mean": float(img.mean()),
        "std": float(img.std()),
        "min": int(img.min()),
        "max": int(img.max()),
        "saturated_fraction": clip.fraction(img),
        "clip_level_dn": clip.dn,
        "clip_source": clip.source,
        "channels": channels,
    }
