"""Focusing aids: where the lens must focus behind a port, the setting to use and the close-up lens it needs.

Conventions: distances in metres from the lens's entrance pupil along the optical axis (a lens's focus scale is
marked from the sensor plane: the two differ by the pupil-to-sensor length, a few centimetres, which matters for
the close virtual images of domes; take it into account when reading a focus scale). Powers in dioptres (1/m).

- The lens must focus on the image the port forms of the target: behind a flat port its apparent position
  (`uwlab.model.port.flat_apparent_distance`), behind a dome its virtual image (`dome_virtual_distance`, taken
  from the dome's centre of curvature; a pupil decentred by δz towards the dome sees it at v(s + δz) − δz).
- A lens that focuses no closer than s_min reaches an image at v < s_min with a supplementary close-up lens of
  power P, which makes a lens focused at s see sharp at 1 / (P + 1/s) (thin lenses in contact; Ray, Applied
  Photographic Optics, 3rd ed., 2002, "Close-up and macrophotography"). The weakest one that works, with the
  lens at its closest focus, has P = 1/v − 1/s_min; then the focus setting is s_min. Otherwise P = 0 and the
  setting is v.
"""

from __future__ import annotations

import numpy as np

from uwlab.model import port as port_model


def target_image_distance_m(s_m, port, water_index, flat=(0.0, 0.0, 1.0), dome=None, decenter_z_m=0.0):
    """Distance from the pupil of the image (apparent position or virtual image) of a target at s_m.

    flat = (air_gap_m, thickness_m, port_index); dome = (radius_m, thickness_m, port_index).
    """
    if port == "dome":
        radius_m, thickness_m, port_index = dome
        dz = np.asarray(decenter_z_m, float)
        shifted = np.asarray(s_m) + dz
        return port_model.dome_virtual_distance(shifted, radius_m, thickness_m, water_index, port_index) - dz
    return port_model.flat_apparent_distance(s_m, water_index, *flat)


def close_up_lens_dpt(image_distance_m, min_focus_distance_m):
    """Power of the weakest close-up lens that lets a lens focusing no closer than s_min see an image at v:
    max(0, 1/v − 1/s_min) [dpt]; NaN when s_min is unknown (None)."""
    if min_focus_distance_m is None:
        return np.full(np.shape(image_distance_m), np.nan)
    return np.maximum(0.0, 1.0 / np.asarray(image_distance_m, float) - 1.0 / np.asarray(min_focus_distance_m, float))


def focus_setting_m(image_distance_m, min_focus_distance_m):
    """The distance to set on the lens: the image distance when the lens reaches it (or s_min is unknown),
    else its closest focus (with the close-up lens of `close_up_lens_dpt`)."""
    v = np.asarray(image_distance_m, float)
    if min_focus_distance_m is None:
        return v
    return np.maximum(v, np.asarray(min_focus_distance_m, float))
