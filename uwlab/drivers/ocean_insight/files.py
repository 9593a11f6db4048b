"""Ocean Insight's own files, read as they are shipped and written in Ocean's layout (docs/spectrometers.md).

- **Irradiance calibration** ``*_OOIIrrad.cal`` (OceanView's absolute-irradiance wizard, SpectraSuite before it,
  whose ``.IrradCal`` has the same layout): ``Key:<TAB>value`` header lines (``Date:``, ``Spectrometer:``,
  ``Integration Time (sec):``, ``Fiber (micron):`` …), then a line ``[uJoule/count]`` and one
  ``wavelength<TAB>factor`` row per pixel: C(λ) in µJ/count, 0 where it was not calibrated
  (`read_ocean_calibration`, `write_ocean_calibration`). ``Fiber (micron)`` is the diameter of the collecting optic
  the calibration was made with — the bare fibre's core, or the diffuser of a cosine corrector (3900 for a CC-3) —
  and gives the collection area A = π (d/2)² (`area_cm2_of_diameter_um`).
- **Calibration lamp data** ``.LMP`` (shipped with Ocean's HL-3P-CAL / HL-2000-CAL / DH-3P-CAL lamps): no header, one
  ``wavelength<TAB>irradiance`` row per line, the lamp's spectral irradiance at the optic in µW/cm²/nm
  (`read_lamp`).
- **Spectrum exports** of OceanView ("ASCII with header") and SpectraSuite: ``Key: value`` header lines, a line
  ``>>>>>Begin Spectral Data<<<<<`` (SpectraSuite: ``>>>>>Begin Processed Spectral Data<<<<<``), tab-separated
  ``wavelength<TAB>value`` rows, optionally ``>>>>>End Spectral Data<<<<<`` (`read_oceanview_spectrum`). The
  integration time comes from ``Integration Time (sec)`` (OceanView) or ``Integration Time (usec)``
  (SpectraSuite).

Each file is read through `uwlab.model.data.read_text` (a bounded regular-file read); a file that is not what it
should be — a ``.cal`` without wavelength rows, a lamp with negative irradiance, an export without its Begin marker,
wavelengths that do not strictly increase — is a `ConfigError` naming the option, the file and the line.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError
from uwlab.model.data import MAX_CSV_BYTES, read_text

CALIBRATION_MARKER = "[uJoule/count]"
BEGIN_MARKERS = (">>>>>Begin Spectral Data<<<<<", ">>>>>Begin Processed Spectral Data<<<<<")
END_MARKERS = (">>>>>End Spectral Data<<<<<", ">>>>>End Processed Spectral Data<<<<<")
FIBRE_KEYS = ("Fiber (micron)", "Fibre (micron)")
FIBRE_UM_RANGE = (5.0, 50_000.0)
"""A collecting optic's diameter [µm] in a ``.cal``: an 8 µm single-mode fibre … a 50 mm sphere port; 3.9 is mm."""
COSINE_CORRECTOR_DIAMETER_MM = {"CC-3": 3.9, "CC-3-UV-S": 3.9, "CC-3-UV-T": 3.9, "CC-3-DA": 7.14}
"""Diffuser diameters of Ocean's cosine correctors [mm] (Ocean Optics' CC-3 family specifications, tabulated from
Ocean's documents by the r4photobiology ``ooacquire`` package, ``oo_calib2irrad_mult``)."""
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def area_cm2_of_diameter_um(diameter_um: float) -> float:
    """The collection area A [cm²] of a circular optic of diameter ``diameter_um`` [µm]: π (d/2)², d in cm.

    >>> round(area_cm2_of_diameter_um(3900.0), 5)  # a CC-3's 3.9 mm diffuser
    0.11946
    """
    return math.pi * (diameter_um * 1e-4 / 2.0) ** 2


def cosine_corrector_area_cm2(name: str) -> float:
    """A [cm²] of Ocean's cosine corrector ``name`` (`COSINE_CORRECTOR_DIAMETER_MM`); `ConfigError` on
    ``cosine-corrector`` for an unknown one."""
    diameter_mm = COSINE_CORRECTOR_DIAMETER_MM.get(name.upper())
    if diameter_mm is None:
        raise ConfigError(
            "cosine-corrector",
            name,
            f"not a known cosine corrector ({', '.join(COSINE_CORRECTOR_DIAMETER_MM)}); give --area-cm2 instead",
        )
    return area_cm2_of_diameter_um(diameter_mm * 1000.0)


@dataclass(frozen=True)
class OceanCalibration:
    """An ``OOIIrrad.cal``: C(λ) [µJ/count], its header, and the collecting optic's diameter where it says one."""

    wavelength_nm: np.ndarray
    uj_per_count: np.ndarray
    header: dict[str, str] = field(default_factory=dict)
    fibre_um: float | None = None

    @property
    def area_cm2(self) -> float | None:
        return None if self.fibre_um is None else area_cm2_of_diameter_um(self.fibre_um)


@dataclass(frozen=True)
class ExportedSpectrum:
    """An OceanView/SpectraSuite spectrum export: wavelengths, values, header and its integration time [s]."""

    wavelength_nm: np.ndarray
    values: np.ndarray
    header: dict[str, str]
    integration_s: float | None


def _header_entry(line: str) -> tuple[str, str]:
    """``Key:<TAB>value`` / ``Key: value`` / ``Key<TAB>value`` → (key without the colon, value)."""
    if ":" in line and (("\t" not in line) or line.index(":") < line.index("\t")):
        key, value = line.split(":", 1)
    elif "\t" in line:
        key, value = line.split("\t", 1)
    else:
        key, value = line, ""
    return key.strip(), value.strip()


def _first_number(text: str) -> float | None:
    match = _NUMBER.search(text)
    return None if match is None else float(match.group())


def _rows(lines: list[str], first: int, key: str, path: Path, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Two numeric columns (tab or space separated) of ``lines`` (file line numbers from ``first``); blank lines
    are skipped; the wavelengths must strictly increase."""
    wavelength, value = [], []
    previous = -math.inf
    for number, line in enumerate(lines, start=first):
        fields = line.split()
        if not fields:
            continue
        if len(fields) < 2:
            raise ConfigError(key, str(path), f"line {number}: {line.strip()!r} is not a wavelength and a {what}")
        try:
            w, v = float(fields[0]), float(fields[1])
        except ValueError:
            raise ConfigError(
                key, str(path), f"line {number}: {line.strip()!r} is not a wavelength and a {what}"
            ) from None
        if not (math.isfinite(w) and math.isfinite(v)):
            raise ConfigError(key, str(path), f"line {number}: {line.strip()!r} is not finite")
        if w <= previous:
            word = "repeats" if w == previous else "is below"
            raise ConfigError(
                key,
                str(path),
                f"line {number}: wavelength {w:g} nm {word} the previous {previous:g} nm "
                "(wavelengths must strictly increase)",
            )
        previous = w
        wavelength.append(w)
        value.append(v)
    if len(wavelength) < 2:
        raise ConfigError(key, str(path), f"has {len(wavelength)} wavelength rows; needs at least 2")
    return np.array(wavelength), np.array(value)


def is_ocean_calibration(path: str | Path, text: str) -> bool:
    """Whether a calibration file is Ocean's ``.cal`` layout (by its suffix or its ``[uJoule/count]`` line)."""
    return Path(path).suffix.lower() == ".cal" or any(
        line.strip().lower() == CALIBRATION_MARKER.lower() for line in text.splitlines()
    )


def read_ocean_calibration(path: str | Path, key: str = "calibration", text: str | None = None) -> OceanCalibration:
    """An ``OOIIrrad.cal`` (or SpectraSuite's ``.IrradCal``, the same layout; module docstring): header, then
    ``[uJoule/count]``, then wavelength/factor rows.

    Ocean's files mark the wavelengths they were not calibrated at — outside the lamp file's range — with a factor
    of 0: leading and trailing zero factors are dropped, so the calibration covers the span between them (a
    reading beyond it is refused, as for any calibration that does not cover the device). `ConfigError` on ``key``
    without the marker; without wavelengths (no rows, or rows of one value each: coefficients without their
    wavelengths); with wavelengths that do not strictly increase; with a factor that is negative, or zero between
    calibrated ones (a count always stands for some energy); or with a ``Fiber (micron)`` that is not a diameter
    in µm."""
    path = Path(path)
    text = read_text(path, key, MAX_CSV_BYTES, "calibration") if text is None else text
    lines = text.splitlines()
    marker = next((i for i, line in enumerate(lines) if line.strip().lower() == CALIBRATION_MARKER.lower()), None)
    if marker is None:
        raise ConfigError(key, str(path), f"no {CALIBRATION_MARKER} line: not an Ocean irradiance calibration")
    header = dict(_header_entry(line) for line in lines[:marker] if line.strip())
    rows = [line for line in lines[marker + 1 :] if line.strip()]
    if not rows:
        raise ConfigError(key, str(path), f"no wavelength rows after {CALIBRATION_MARKER}")
    if all(len(line.split()) == 1 for line in rows):
        raise ConfigError(
            key,
            str(path),
            f"no wavelengths: its {len(rows)} rows hold one value each (factors without their wavelengths); "
            "give the calibration whose rows are wavelength<TAB>µJ/count",
        )
    wavelength_nm, factor = _rows(lines[marker + 1 :], marker + 2, key, path, "µJ/count factor")
    calibrated = np.flatnonzero(factor != 0)
    if calibrated.size < 2:
        raise ConfigError(key, str(path), "every µJ/count factor is 0: nothing is calibrated")
    span = slice(calibrated[0], calibrated[-1] + 1)
    wavelength_nm, factor = wavelength_nm[span], factor[span]
    if np.any(factor <= 0):
        i = int(np.argmax(factor <= 0))
        raise ConfigError(key, str(path), f"µJ/count must be positive; at {wavelength_nm[i]:g} nm it is {factor[i]:g}")
    fibre_um = None
    fibre_text = next((header[k] for k in FIBRE_KEYS if k in header), None)
    if fibre_text is not None:
        fibre_um = _first_number(fibre_text)
        low, high = FIBRE_UM_RANGE
        if fibre_um is None or not low <= fibre_um <= high:
            raise ConfigError(
                key,
                str(path),
                f"Fiber (micron) = {fibre_text!r}: must be the optic's diameter in µm ({low:g}–{high:g}; CC-3: 3900)",
            )
    return OceanCalibration(wavelength_nm, factor, header, fibre_um)


def read_lamp(path: str | Path, key: str = "lamp") -> tuple[np.ndarray, np.ndarray]:
    """(wavelength_nm, E [µW/cm²/nm]) of a lamp data file ``.LMP`` (no header, tab-separated rows). `ConfigError` on
    ``key`` for a row that is not two numbers, wavelengths that do not strictly increase, or a negative
    irradiance (a lamp emits; a negative value is a corrupt file or a difference, not a lamp)."""
    path = Path(path)
    text = read_text(path, key, MAX_CSV_BYTES, "lamp")
    wavelength_nm, irradiance = _rows(text.splitlines(), 1, key, path, "irradiance")
    if np.any(irradiance < 0):
        i = int(np.argmax(irradiance < 0))
        raise ConfigError(
            key,
            str(path),
            f"negative irradiance {irradiance[i]:g} µW/cm²/nm at {wavelength_nm[i]:g} nm (a lamp's irradiance is ≥ 0)",
        )
    return wavelength_nm, irradiance


def read_oceanview_spectrum(path: str | Path, key: str = "spectrum") -> ExportedSpectrum:
    """An OceanView/SpectraSuite export (module docstring). `ConfigError` on ``key`` without the Begin marker,
    without rows, or with wavelengths that do not strictly increase."""
    path = Path(path)
    text = read_text(path, key, MAX_CSV_BYTES, "spectrum")
    lines = text.splitlines()
    begin = next((i for i, line in enumerate(lines) if line.strip() in BEGIN_MARKERS), None)
    if begin is None:
        raise ConfigError(
            key, str(path), f"no {BEGIN_MARKERS[0]} line: not an OceanView spectrum export (ASCII with header)"
        )
    end = next((i for i in range(begin + 1, len(lines)) if lines[i].strip() in END_MARKERS), len(lines))
    header = dict(_header_entry(line) for line in lines[:begin] if line.strip())
    wavelength_nm, values = _rows(lines[begin + 1 : end], begin + 2, key, path, "value")
    integration_s = None
    if "Integration Time (sec)" in header:
        integration_s = _first_number(header["Integration Time (sec)"])
    elif "Integration Time (usec)" in header:
        usec = _first_number(header["Integration Time (usec)"])
        integration_s = None if usec is None else usec * 1e-6
    if integration_s is not None and not integration_s > 0:
        raise ConfigError(key, str(path), f"integration time {integration_s:g} s: must be positive")
    return ExportedSpectrum(wavelength_nm, values, header, integration_s)


def _write_new(path: str | Path, key: str, text: str) -> Path:
    path = Path(path)
    try:
        with open(path, "x", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
    except FileExistsError:
        raise ConfigError(key, str(path), "file exists; refusing to overwrite it") from None
    except OSError as exc:
        raise ConfigError(key, str(path), f"cannot write ({exc.strerror})") from None
    return path


def write_ocean_calibration(
    path: str | Path,
    wavelength_nm: np.ndarray,
    uj_per_count: np.ndarray,
    header: dict[str, str],
    key: str = "out-cal",
) -> Path:
    """Write C(λ) in Ocean's ``OOIIrrad.cal`` layout (``header`` as ``Key:<TAB>value`` lines, ``[uJoule/count]``,
    then ``wavelength<TAB>factor`` rows); an existing file is never replaced."""
    lines = [f"{k}:\t{v}" for k, v in header.items()]
    lines.append(CALIBRATION_MARKER)
    lines += [f"{w:.6f}\t{c:.9E}" for w, c in zip(wavelength_nm, uj_per_count, strict=True)]
    return _write_new(path, key, "\n".join(lines) + "\n")


def write_calibration_csv(
    path: str | Path, wavelength_nm: np.ndarray, uj_per_count: np.ndarray, comments: list[str], key: str = "out-csv"
) -> Path:
    """Write C(λ) as uwlab's CSV (``wavelength_nm,uJ_per_count``, ``#`` comment lines first; full precision); an
    existing file is never replaced."""
    lines = [f"# {c}" for c in comments] + ["wavelength_nm,uJ_per_count"]
    lines += [f"{float(w)!r},{float(c)!r}" for w, c in zip(wavelength_nm, uj_per_count, strict=True)]
    return _write_new(path, key, "\n".join(lines) + "\n")
