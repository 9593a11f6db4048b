"""`uwlab spectrum`: read the spectrometer (or import a Sekonic C-7000 CSV) and derive lux, W/m², photons, CCT."""

from __future__ import annotations

import json

from uwlab.drivers.serial import PROTOCOLS, open_spectrometer
from uwlab.drivers.serial.base import check_averaging, check_integration_ms
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.spectra import read_sekonic_csv, spectrum_summary, write_spectrum_csv
from uwlab.outputs import output_file


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "spectrum", description="Spectral irradiance from the spectrometer or a Sekonic C-7000 CSV export."
    )
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--port", help="serial port of the spectrometer")
    source.add_argument("--import", dest="import_path", metavar="FILE.csv", help="Sekonic C-7000 CSV export")
    p.add_argument("--protocol", choices=PROTOCOLS, default=PROTOCOLS[0], help="instrument protocol")
    p.add_argument("--integration-ms", type=float, help="integration time [ms]")
    p.add_argument("--average", type=int, help="number of spectra averaged")
    p.add_argument("--out", metavar="FILE.csv", help="write wavelength_nm,irradiance_w_m2_nm (never overwritten)")
    p.add_argument(
        "--json",
        action="store_true",
        help='print one JSON object (with "saturated": whether the spectrometer saturated; null for an import)',
    )
    p.set_defaults(func=run)


def run(args) -> int:
    if args.out is not None:
        output_file(args.out, "--out")
    if args.import_path is not None:
        if args.integration_ms is not None or args.average is not None:
            raise ConfigError("import", args.import_path, "--integration-ms and --average need --port")
        (wavelength_nm, irradiance), saturated = read_sekonic_csv(args.import_path), None
    else:
        (wavelength_nm, irradiance), saturated = _measure(args)
    summary = {**spectrum_summary(wavelength_nm, irradiance), "saturated": saturated}
    if args.out is not None:
        write_spectrum_csv(args.out, wavelength_nm, irradiance)
    if args.json:
        print(json.dumps(summary))
    else:
        _print_summary(summary)
    return 0


def _measure(args) -> tuple[tuple, bool]:
    """((wavelength_nm, irradiance_w_m2_nm), whether the spectrometer saturated) from the instrument."""
    if args.integration_ms is not None:
        check_integration_ms(args.integration_ms)
    if args.average is not None:
        check_averaging(args.average)
    with open_spectrometer(args.port, args.protocol) as spectrometer:
        if args.integration_ms is not None:
            spectrometer.set_integration_ms(args.integration_ms)
        if args.average is not None:
            spectrometer.set_averaging(args.average)
        return spectrometer.read_spectrum(), spectrometer.last_saturated


def _print_summary(summary: dict) -> None:
    wavelength_nm = summary["wavelength_nm"]
    cct = summary["cct_k"]
    print(f"spectrum: {len(wavelength_nm)} samples, {wavelength_nm[0]:g}–{wavelength_nm[-1]:g} nm")
    print(f"irradiance      {summary['irradiance_w_m2']:.6g} W/m²")
    print(f"illuminance     {summary['illuminance_lux']:.6g} lx")
    print(f"photon flux     {summary['photon_flux_m2_s']:.6g} m⁻² s⁻¹")
    print(f"CCT             {'undefined' if cct is None else f'{cct:.0f} K'}")
    if summary["saturated"]:
        print("saturated       yes: the readings are clipped; reduce --integration-ms")
