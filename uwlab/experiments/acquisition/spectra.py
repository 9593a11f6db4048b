"""Measured spectral irradiance: derived quantities, Sekonic C-7000 import, CSV export.

A spectrum is a pair of 1-D arrays (wavelength_nm strictly increasing, irradiance_w_m2_nm). Integrals
use the trapezoidal rule over the measured range.

- irradiance E = ∫ E(λ) dλ [W/m²];
- illuminance Ev = K_m ∫ E(λ) V(λ) dλ [lx], K_m = 683.002 lm/W, V = CIE 1924 photopic luminosity
  function (`uwlab.model.photometry.photopic_v_at`), zero outside its table (CIE 15:2018);
- photon flux Φp = ∫ E(λ) λ / (h c) dλ [m⁻² s⁻¹] (`uwlab.model.photometry.photon_flux`);
- CCT from the CIE 1931 2° chromaticity: XYZ = ∫ E x̄ȳz̄ dλ, xy → CIE 1960 uv → Ohno (2013),
  "Practical use and calculation of CCT and Duv", LEUKOS 10(1), via colour-science ``uv_to_CCT`` (imported
  only for CCT: importing colour-science costs seconds).

The Sekonic C-7000 CSV export lists ``Spectral Data <λ>[nm],<W/m²/nm>`` rows: a 5 nm block, then a 1 nm block,
each over 380–780 nm. `read_sekonic_csv` keeps the 1 nm block (the 5 nm one when it is alone) and trusts nothing
else: every data row must hold a wavelength in `SEKONIC_RANGE_NM` and a finite value in
[0, `SEKONIC_MAX_W_M2_NM`]; within a block wavelengths increase by one step (1 or 5 nm) from the first to the last
of the range, without gaps, repeats or strays; a block of each step at most. A file breaking a rule is refused in
one line naming the line. A file whose rows are separated by semicolons may use decimal commas (as Sekonic's
software writes under a European locale) and is read as such; in a comma-separated file a decimal comma splits a
value in two, and the row is refused as one (never read as the integer part). `SEKONIC_MAX_W_M2_NM` is an assumed
plausibility limit, 50 times the peak spectral
irradiance of sunlight at sea level (about 2 W m⁻² nm⁻¹): beyond it a value is a unit error or corruption.
"""

from __future__ import annotations

import csv
import math
import re
from functools import lru_cache
from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError
from uwlab.model.data import MAX_CSV_BYTES, read_bytes
from uwlab.model.photometry import K_M_LM_PER_W, photon_flux, photopic_v_at

SEKONIC_ROW = re.compile(r"\s*Spectral Data\s+(\S+?)\s*\[nm\]\s*")
SEKONIC_RANGE_NM = (380.0, 780.0)
SEKONIC_STEPS_NM = (1.0, 5.0)
SEKONIC_MAX_W_M2_NM = 100.0
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
def _cmfs_table() -> tuple[np.ndarray, np.ndarray]:
    import colour

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    return cmfs.wavelengths, cmfs.values


def illuminance_lux(wavelength_nm: np.ndarray, irradiance_w_m2_nm: np.ndarray) -> float:
    return float(K_M_LM_PER_W * np.trapezoid(irradiance_w_m2_nm * photopic_v_at(wavelength_nm), wavelength_nm))


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
    import colour

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
    """(wavelength_nm, irradiance_w_m2_nm) from a Sekonic C-7000 CSV export, validated (see the module docstring);
    `ConfigError` on ``import`` naming the offending line."""
    path = Path(path)
    raw = read_bytes(path, "import", MAX_CSV_BYTES, "CSV")
    text = raw.decode("utf-8-sig") if _is_utf8(raw) else raw.decode("latin-1")
    data_lines = [line for line in text.splitlines() if line.lstrip().startswith("Spectral Data")]
    delimiter = ";" if data_lines and ";" in data_lines[0] else ","
    blocks: list[list[tuple[int, float, float]]] = []
    for line, row in enumerate(csv.reader(text.splitlines(), delimiter=delimiter), start=1):
        if not row or not row[0].lstrip().startswith("Spectral Data"):
            continue
        sample = (line, *_sekonic_row(path, line, row, decimal_comma=delimiter == ";"))
        if blocks and sample[1] > blocks[-1][-1][1]:
            blocks[-1].append(sample)
        elif blocks and not (blocks[-1][-1][1] == SEKONIC_RANGE_NM[1] and sample[1] == SEKONIC_RANGE_NM[0]):
            raise _sekonic_error(
                path,
                line,
                row,
                f"{sample[1]:g} nm after {blocks[-1][-1][1]:g} nm: wavelengths "
                "must increase within a block (a repeated or stray row)",
            )
        else:
            blocks.append([sample])
    if not blocks:
        raise ConfigError("import", str(path), "no 'Spectral Data <λ>[nm]' rows: not a Sekonic C-7000 CSV")
    by_step: dict[float, list[tuple[int, float, float]]] = {}
    for block in blocks:
        step = _sekonic_step(path, block)
        if step in by_step:
            raise ConfigError("import", str(path), f"line {block[0][0]}: a second {step:g} nm block")
        by_step[step] = block
    chosen = by_step.get(1.0) or by_step[5.0]
    return np.array([nm for _, nm, _ in chosen]), np.array([value for _, _, value in chosen])


def _sekonic_row(path: Path, line: int, row: list[str], decimal_comma: bool = False) -> tuple[float, float]:
    """(λ, value) of one data row, both within their ranges; with ``decimal_comma`` (a semicolon-separated file)
    a comma in a number is its decimal mark."""
    match = SEKONIC_ROW.fullmatch(row[0])
    if not match or len(row) < 2:
        raise _sekonic_error(path, line, row, "not a 'Spectral Data <λ>[nm],<value>' row")
    if any(cell.strip() for cell in row[2:]):
        raise _sekonic_error(
            path,
            line,
            row,
            f"{len(row)} fields where 2 belong: a decimal comma in a "
            "comma-separated file? Export with decimal points (0.5, not 0,5) or "
            "separated by semicolons",
        )
    number = (lambda text: float(text.replace(",", "."))) if decimal_comma else float
    try:
        nm, value = number(match.group(1)), number(row[1])
    except ValueError:
        raise _sekonic_error(path, line, row, "wavelength and value must be numbers") from None
    lo, hi = SEKONIC_RANGE_NM
    if not lo <= nm <= hi:
        raise _sekonic_error(path, line, row, f"{nm:g} nm is outside the C-7000's {lo:g}–{hi:g} nm")
    if not (math.isfinite(value) and 0.0 <= value <= SEKONIC_MAX_W_M2_NM):
        raise _sekonic_error(path, line, row, f"{value:g} W/m²/nm is outside [0, {SEKONIC_MAX_W_M2_NM:g}]")
    return nm, value


def _sekonic_step(path: Path, block: list[tuple[int, float, float]]) -> float:
    """The step of a block covering the whole range in equal steps of `SEKONIC_STEPS_NM`."""
    lo, hi = SEKONIC_RANGE_NM
    first_line, first_nm, _ = block[0]
    if first_nm != lo:
        raise ConfigError("import", str(path), f"line {first_line}: a block starts at {first_nm:g} nm, not {lo:g} nm")
    if len(block) < 2 or block[1][1] - first_nm not in SEKONIC_STEPS_NM:
        raise ConfigError(
            "import",
            str(path),
            f"line {first_line}: a block must step by "
            f"{' or '.join(f'{s:g}' for s in SEKONIC_STEPS_NM)} nm from {lo:g} nm",
        )
    step = block[1][1] - first_nm
    for (_, previous, _), (line, nm, _) in zip(block, block[1:], strict=False):
        if nm - previous != step:
            raise ConfigError(
                "import",
                str(path),
                f"line {line}: {previous:g} → {nm:g} nm breaks the {step:g} nm "
                f"steps (missing {previous + step:g}–{nm - step:g} nm)",
            )
    last_line, last_nm, _ = block[-1]
    if last_nm != hi:
        raise ConfigError(
            "import", str(path), f"line {last_line}: the {step:g} nm block ends at {last_nm:g} nm, not {hi:g} nm"
        )
    return step


def _sekonic_error(path: Path, line: int, row: list[str], reason: str) -> ConfigError:
    return ConfigError("import", str(path), f"line {line} {','.join(row)[:60]!r}: {reason}")


def _is_utf8(raw: bytes) -> bool:
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


def write_spectrum_csv(path: str | Path, wavelength_nm: np.ndarray, irradiance_w_m2_nm: np.ndarray) -> Path:
    """Write ``wavelength_nm,irradiance_w_m2_nm`` rows to a new file; an existing file is never replaced."""
    path = Path(path)
    try:
        with open(path, "x", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(CSV_COLUMNS)
            writer.writerows(
                (repr(float(w)), repr(float(e))) for w, e in zip(wavelength_nm, irradiance_w_m2_nm, strict=True)
            )
    except FileExistsError:
        raise ConfigError("out", str(path), "file exists; refusing to overwrite it") from None
    except OSError as exc:
        raise ConfigError("out", str(path), f"cannot write ({exc.strerror})") from None
    return path
