"""Measured spectral irradiance: derived quantities, Sekonic C-7000 import, CSV export.

A spectrum is a pair of 1-D arrays (wavelength_nm strictly increasing, irradiance_w_m2_nm). Integrals
use the trapezoidal rule over the measured range.

- irradiance E = ∫ E(λ) dλ [W/m²];
- illuminance Ev = K_m ∫ E(λ) V(λ) dλ [lx], K_m = 683.002 lm/W, V = CIE 1924 photopic luminosity
  function (colour-science ``SDS_LEFS_PHOTOPIC``), zero outside its table (CIE 15:2018);
- photon flux Φp = ∫ E(λ) λ / (h c) dλ [m⁻² s⁻¹] (`uwlab.model.photometry.photon_flux`);
- CCT from the CIE 1931 2° chromaticity: XYZ = ∫ E x̄ȳz̄ dλ, xy → CIE 1960 uv → Ohno (2013),
  "Practical use and calculation of CCT and Duv", LEUKOS 10(1), via colour-science ``uv_to_CCT``.

The Sekonic C-7000 CSV export lists ``Spectral Data <λ>[nm],<W/m²/nm>`` rows: a 5 nm block, then a
1 nm block over the same range; repeated wavelengths are dropped keeping the later (1 nm) value.
"""
from __future__ import annotations

import csv
import math
import re
from functools import lru_cache
from pathlib import Path

import colour
import numpy as np

from uwlab.errors import ConfigError
from uwlab.model.photometry import K_M_LM_PER_W, photon_flux

SEKONIC_ROW = re.compile(r"\s*Spectral Data\s+(\d+(?:\.\d+)?)\s*\[nm\]\s*")
CSV_COLUMNS = ("wavelength_nm", "irradiance_w_m2_nm")


def check_spectrum(wavelength_nm, irradiance_w_m2_nm, key: str = "spectrum") -> tuple[np.ndarray, np.ndarray]:
    """Validated float arrays: 1-D, equal length ≥ 2, finite, wavelengths strictly increasing."""
    wavelength_nm = np.asarray(wavelength_nm, dtype=float)
    irradiance = np.asarray(irradiance_w_m2_nm, dtype=float)
    if wavelength_nm.ndim != 1 or wavelength_nm.shape != irradiance.shape or wavelength_nm.size < 2:
        raise ConfigError(key, f"{wavelength_nm.size} wavelengths", "needs ≥ 2 wavelength/irradiance pairs")
    if not (np.all(np.isfinite(wavelength_nm)) and np.all(np.isfinite(irradiance))):
        raise ConfigError(key, "non-finite values", "wavelengths and irradiances must be finite")
    if np.any(np.diff(wavelength_nm) <= 0):
        raise ConfigError(key, "wavelength_nm", "must be strictly increasing")
    return wavelength_nm, irradiance


def irradiance_w_m2(wavelength_nm: np.ndarray, irradiance_w_m2_nm: np.ndarray) -> float:
    return float(np.trapezoid(irradiance_w_m2_nm, wavelength_nm))


@lru_cache(maxsize=1)
def _photopic_table() -> tuple[np.ndarray, np.ndarray]:
    sd = colour.colorimetry.SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"]
    return sd.wavelengths, sd.values


@lru_cache(maxsize=1)
def _cmfs_table() -> tuple[np.ndarray, np.ndarray]:
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    return cmfs.wavelengths, cmfs.values


def illuminance_lux(wavelength_nm: np.ndarray, irradiance_w_m2_nm: np.ndarray) -> float:
    table_nm, v = _photopic_table()
    v_at = np.interp(wavelength_nm, table_nm, v, left=0.0, right=0.0)
    return float(K_M_LM_PER_W * np.trapezoid(irradiance_w_m2_nm * v_at, wavelength_nm))


def tristimulus(wavelength_nm: np.ndarray, irradiance_w_m2_nm: np.ndarray) -> np.ndarray:
    """Unnormalised CIE 1931 2° XYZ = ∫ E(λ) (x̄, ȳ, z̄) dλ."""
    table_nm, cmfs = _cmfs_table()
    at = np.stack([np.interp(wavelength_nm, table_nm, c, left=0.0, right=0.0) for c in cmfs.T], axis=-1)
    return np.trapezoid(np.asarray(irradiance_w_m2_nm)[:, None] * at, wavelength_nm, axis=0)


def cct_k(wavelength_nm: np.ndarray, irradiance_w_m2_nm: np.ndarray) -> float:
    """Correlated colour temperature [K] (Ohno 2013); NaN when the spectrum has no visible light."""
    xyz = tristimulus(wavelength_nm, irradiance_w_m2_nm)
    if not (np.all(xyz >= 0) and xyz.sum() > 0):
        return math.nan
    uv = colour.xy_to_UCS_uv(xyz[:2] / xyz.sum())
    return float(colour.uv_to_CCT(uv, method="Ohno 2013")[0])


def spectrum_summary(wavelength_nm, irradiance_w_m2_nm) -> dict:
    """The spectrum and its derived quantities, keyed as in ``uwlab spectrum --json``; NaN becomes None."""
    wavelength_nm, irradiance = check_spectrum(wavelength_nm, irradiance_w_m2_nm)
    cct = cct_k(wavelength_nm, irradiance)
    return {
        "wavelength_nm": wavelength_nm.tolist(),
        "irradiance_w_m2_nm": irradiance.tolist(),
        "irradiance_w_m2": irradiance_w_m2(wavelength_nm, irradiance),
        "illuminance_lux": illuminance_lux(wavelength_nm, irradiance),
        "photon_flux_m2_s": float(photon_flux(wavelength_nm, irradiance)),
        "cct_k": None if math.isnan(cct) else cct,
    }


def read_sekonic_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(wavelength_nm, irradiance_w_m2_nm) from a Sekonic C-7000 CSV export."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ConfigError("import", str(path), f"cannot read ({exc.strerror})") from None
    text = raw.decode("utf-8-sig") if _is_utf8(raw) else raw.decode("latin-1")
    values: dict[float, float] = {}
    for row in csv.reader(text.splitlines()):
        match = SEKONIC_ROW.fullmatch(row[0]) if row else None
        if match and len(row) >= 2:
            values[float(match.group(1))] = _sekonic_value(path, row)
    if len(values) < 2:
        raise ConfigError("import", str(path), "no 'Spectral Data <λ>[nm]' rows: not a Sekonic C-7000 CSV")
    wavelength_nm = np.array(sorted(values))
    return wavelength_nm, np.array([values[w] for w in wavelength_nm])


def _is_utf8(raw: bytes) -> bool:
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


def _sekonic_value(path: Path, row: list[str]) -> float:
    try:
        value = float(row[1])
    except ValueError:
        raise ConfigError("import", str(path), f"row {row[0]!r} has a non-numeric value {row[1]!r}") from None
    if not math.isfinite(value):
        raise ConfigError("import", str(path), f"row {row[0]!r} has a non-finite value {row[1]!r}")
    return value


def write_spectrum_csv(path: str | Path, wavelength_nm: np.ndarray, irradiance_w_m2_nm: np.ndarray) -> Path:
    """Write ``wavelength_nm,irradiance_w_m2_nm`` rows to a new file; an existing file is never replaced."""
    path = Path(path)
    try:
        with open(path, "x", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(CSV_COLUMNS)
            writer.writerows((repr(float(w)), repr(float(e))) for w, e in zip(wavelength_nm, irradiance_w_m2_nm))
    except FileExistsError:
        raise ConfigError("out", str(path), "file exists; refusing to overwrite it") from None
    except OSError as exc:
        raise ConfigError("out", str(path), f"cannot write ({exc.strerror})") from None
    return path
