"""Housing ports: transmittance and the geometry of flat and dome ports.

Conventions: distances in metres measured from the camera's entrance pupil, which sits at the flat port's inner
face or at the dome's centre of curvature (a centred dome). Indices: water n_w, port material n_p, air 1.

- Radiance entering the housing L_a = L_w · T_port / n_w² (invariance of basic radiance L/n², e.g. Boyd,
  Radiometry and the Detection of Optical Radiation, 1983, §5.3), for flat and dome ports alike.
- T_port: two surfaces with normal-incidence Fresnel reflectances R = ((n₁ − n₂)/(n₁ + n₂))² (Hecht, Optics,
  5th ed., eq. 4.67) and incoherent multiple reflections, T = T₁T₂ / (1 − R₁R₂); absorption in the port neglected.
- Flat port (paraxial): an object at distance s from the pupil, behind an air gap g (pupil → inner face) and a
  window of thickness t and index n_p, appears at g + t / n_p + (s − g − t) / n_w (apparent depth through each
  plane layer, Hecht §5.2.3) with its lateral size unchanged; with g = t = 0 (today's default) that is s / n_w.
  The effective focal length is f_uw = n_w · f and the field of view shrinks. Exact, off-axis refraction is in
  `uwlab.model.raytrace`.
- Dome port (thick, concentric): Gaussian refraction at each spherical surface, n₁/s_o + n₂/s_i = (n₂ − n₁)/R
  (real-is-positive convention, R > 0 with the centre of curvature on the camera side; Hecht eq. 5.8), first
  water→port at the outer radius R_o, then port→air at R_i = R_o − t. The virtual image of infinity lies at
  ≈ n_w R / (n_w − 1) from the centre for a thin dome.
"""

from __future__ import annotations

import numpy as np


def fresnel_reflectance(n1, n2):
    """Normal-incidence Fresnel reflectance between media of indices n1 and n2."""
    n1, n2 = np.asarray(n1, float), np.asarray(n2, float)
    return ((n1 - n2) / (n1 + n2)) ** 2


def port_transmittance(water_index, port_index):
    """Transmittance of a port window (water → port → air) with incoherent multiple reflections."""
    r1 = fresnel_reflectance(water_index, port_index)
    r2 = fresnel_reflectance(port_index, 1.0)
    return (1 - r1) * (1 - r2) / (1 - r1 * r2)


def _flat_offset(water_index, air_gap_m, thickness_m, port_index):
    """g + t/n_p − (g + t)/n_w: the apparent distance is s/n_w plus this (exactly 0.0 when g = t = 0)."""
    return air_gap_m + thickness_m / port_index - (air_gap_m + thickness_m) / np.asarray(water_index, float)


def flat_apparent_distance(s_m, water_index, air_gap_m=0.0, thickness_m=0.0, port_index=1.0):
    """Paraxial apparent distance from the pupil of an object at s_m behind a flat port (module docstring)."""
    return np.asarray(s_m, float) / water_index + _flat_offset(water_index, air_gap_m, thickness_m, port_index)


def flat_object_distance(v_m, water_index, air_gap_m=0.0, thickness_m=0.0, port_index=1.0):
    """Inverse of `flat_apparent_distance`: the object distance whose apparent distance is v_m."""
    return (np.asarray(v_m, float) - _flat_offset(water_index, air_gap_m, thickness_m, port_index)) * water_index


def dome_virtual_distance(u_m, radius_m, thickness_m, water_index, port_index):
    """Distance from the dome centre of the virtual image of an on-axis object at u_m from the centre."""
    r_o = np.asarray(radius_m, float)
    r_i = r_o - thickness_m
    with np.errstate(divide="ignore", invalid="ignore"):
        so1 = np.asarray(u_m, float) - r_o
        si1 = port_index / ((port_index - water_index) / r_o - water_index / so1)
        so2 = thickness_m - si1
        si2 = 1.0 / ((1.0 - port_index) / r_i - port_index / so2)
    return r_i - si2


def dome_object_distance(v_m, radius_m, thickness_m, water_index, port_index):
    """Inverse of `dome_virtual_distance`: the object distance (from the centre) whose virtual image is at v_m.

    Returns +inf for virtual distances at or beyond the image of infinity.
    """
    r_o = np.asarray(radius_m, float)
    r_i = r_o - thickness_m
    with np.errstate(divide="ignore", invalid="ignore"):
        si2 = r_i - np.asarray(v_m, float)
        so2 = port_index / ((1.0 - port_index) / r_i - 1.0 / si2)
        si1 = thickness_m - so2
        so1 = water_index / ((port_index - water_index) / r_o - port_index / si1)
        u = so1 + r_o
    v_inf = dome_virtual_distance(np.inf, radius_m, thickness_m, water_index, port_index)
    return np.where((np.asarray(v_m) >= v_inf) | ~(u > 0), np.inf, u)
