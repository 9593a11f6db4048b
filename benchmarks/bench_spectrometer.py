"""Ocean Insight counts → irradiance benchmark (JSON on stdout).

A simulated Flame (2048 pixels, electric-dark pixels, a 4–5 % sublinear detector with its stored nonlinearity
coefficients) behind python-seabreeze's ``Spectrometer`` API (tests/support/seabreeze_fake.py) reads a 3100 K
blackbody of known absolute irradiance through the calibration file tests/data/ocean_insight_calibration_3100k.csv.
Reported: the largest relative deviation of the driver's W/m²/nm from the lamp's irradiance over the optical
pixels, and from an independent computation of OceanView's relation on the same raw counts (target: both within
0.1 %), and the time per spectrum through `OceanInsightSpectrometer.read_spectrum` (the simulated readout
included) and through the conversion alone.

Usage: python benchmarks/bench_spectrometer.py [--spectra N]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.support.paths import DATA
from tests.support.seabreeze_fake import (
    CC3_AREA_CM2,
    SimulatedDevice,
    fake_seabreeze,
    lamp_counts_per_s,
    lamp_w_m2_nm,
    neighbour_spread_nm,
    optical,
)
from uwlab.drivers.ocean_insight import OceanInsightSpectrometer, read_calibration
from uwlab.drivers.ocean_insight.radiometry import irradiance_w_m2_nm

INTEGRATION_MS = 10.0


def independent_w_m2_nm(device: SimulatedDevice, raw: np.ndarray, integration_s: float) -> np.ndarray:
    """OceanView's relation written out on raw counts: electric dark = mean of the masked pixels, seabreeze's
    nonlinearity division, C read straight from the file and interpolated, dλ by explicit neighbours."""
    level = raw[device.dark_pixel_indices].mean()
    x = raw - level
    x = x / (1.0 - device.nonlinearity_a * x)
    table = np.loadtxt(DATA / "ocean_insight_calibration_3100k.csv", delimiter=",", comments="#", skiprows=4)
    c_uj = np.interp(device.wavelength_nm, table[:, 0], table[:, 1])
    e_uw_cm2_nm = x * c_uj / (integration_s * CC3_AREA_CM2 * neighbour_spread_nm(device.wavelength_nm))
    return e_uw_cm2_nm * 1e-6 / 1e-4


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spectra", type=int, default=200)
    args = parser.parse_args()
    device = SimulatedDevice()
    device.signal_counts_per_s = lamp_counts_per_s(device)
    mask = optical(device)
    calibration = read_calibration(DATA / "ocean_insight_calibration_3100k.csv")
    with OceanInsightSpectrometer(
        fake_seabreeze(device).from_serial_number(None), calibration, CC3_AREA_CM2, integration_ms=INTEGRATION_MS
    ) as spectrometer:
        wavelength_nm, irradiance = spectrometer.read_spectrum()
        raw = device.raw()
        independent = independent_w_m2_nm(device, raw, INTEGRATION_MS / 1000)
        t0 = time.perf_counter()
        for _ in range(args.spectra):
            spectrometer.read_spectrum()
        per_spectrum_s = (time.perf_counter() - t0) / args.spectra
        counts, _ = spectrometer.read_counts()
        t0 = time.perf_counter()
        for _ in range(args.spectra):
            irradiance_w_m2_nm(
                counts, 0.0, spectrometer.uj_per_count, INTEGRATION_MS / 1000, CC3_AREA_CM2, wavelength_nm
            )
        conversion_s = (time.perf_counter() - t0) / args.spectra
    truth = lamp_w_m2_nm(wavelength_nm)
    print(
        json.dumps(
            {
                "pixels": int(wavelength_nm.size),
                "integration_ms": INTEGRATION_MS,
                "max_rel_error_vs_lamp": float(np.max(np.abs(irradiance[mask] / truth[mask] - 1))),
                "max_rel_error_vs_independent": float(np.max(np.abs(irradiance[mask] / independent[mask] - 1))),
                "target_rel_error": 1e-3,
                "read_spectrum_ms": per_spectrum_s * 1e3,
                "conversion_ms": conversion_s * 1e3,
                "spectra": args.spectra,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
