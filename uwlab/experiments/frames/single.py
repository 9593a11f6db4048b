"""Statistics of one frame, as `uwlab grab` reports them (a sweep's points use the stack statistics of `stack`)."""

from __future__ import annotations

from uwlab.drivers.camera import Frame
from uwlab.experiments.saturation import frame_clip_level
from uwlab.model.sensor import SensorProfile


def frame_statistics(frame: Frame, sensor: SensorProfile | None) -> dict:
    """Statistics of one frame: its identity and settings, mean, standard deviation, extremes, and the fraction of
    saturated pixels by the one rule (`uwlab.experiments.saturation`; the clip level from ``sensor`` at the frame's
    settings when it is given, else from the data)."""
    image, settings = frame.image, frame.settings
    clip = frame_clip_level(frame, sensor)
    return {
        "frame_id": frame.frame_id,
        "timestamp_ns": frame.timestamp_ns,
        "width": int(image.shape[1]),
        "height": int(image.shape[0]),
        "pixel_format": frame.pixel_format,
        "exposure_us": settings.exposure_us,
        "gain_db": settings.gain_db,
        "mean": float(image.mean()),
        "std": float(image.std()),
        "min": int(image.min()),
        "max": int(image.max()),
        "saturated_fraction": clip.fraction(image),
        "clip_level_dn": clip.dn,
        "clip_source": clip.source,
    }
