"""`uwlab spectrometer calibrate`: OceanView's irradiance calibration of an Ocean Insight spectrometer against a
calibration lamp's ``.LMP`` file, written in Ocean's ``OOIIrrad.cal`` layout and uwlab's CSV (docs/spectrometers.md).

The lamp and a dark (light blocked) are read at one integration time — measured on the spectrometer (``--sim``:
the simulated one, lit by the lamp the file describes), or taken from two OceanView exports
(``--lamp-spectrum``, ``--dark-spectrum``) — and

    C(λ) [µJ/count] = E_lamp(λ) [µW/cm²/nm] · T [s] · A [cm²] · dλ [nm] / (S(λ) − D(λ)) [counts]

(`uwlab.drivers.ocean_insight.radiometry.lamp_calibration`). Every input and output path is checked before the
device is opened; nothing is written unless the calibration succeeded, and no file is ever replaced.
"""

from __future__ import annotations

import datetime
import json
import math

import numpy as np

from uwlab.cli.spectrum import add_area_options, add_sim_options, operator, sim_bench
from uwlab.drivers.ocean_insight import open_instrument
from uwlab.drivers.ocean_insight.definition import BACKENDS, load_definition
from uwlab.drivers.ocean_insight.device import collection_area_cm2
from uwlab.drivers.ocean_insight.files import (
    read_lamp,
    read_oceanview_spectrum,
    write_calibration_csv,
    write_ocean_calibration,
)
from uwlab.drivers.ocean_insight.radiometry import check_lamp_covers, lamp_calibration
from uwlab.drivers.serial.base import check_averaging, check_integration_ms
from uwlab.errors import ConfigError
from uwlab.outputs import output_file

EXPORT_INTEGRATION_MATCH = 1e-6
"""The lamp and dark exports' integration times must agree within this fraction."""


def register(subparsers) -> None:
    p = subparsers.add_parser("spectrometer", description="Ocean Insight spectrometer tasks.")
    sub = p.add_subparsers(dest="spectrometer_command", required=True, metavar="TASK")
    c = sub.add_parser(
        "calibrate",
        description="Irradiance calibration [µJ/count] against a calibration lamp (OceanView's procedure): read the "
        "lamp and a dark, write Ocean's *_OOIIrrad.cal and uwlab's CSV.",
    )
    c.add_argument("--lamp", required=True, metavar="FILE.LMP", help="the lamp's data file (µW/cm²/nm at the optic)")
    c.add_argument("--instrument", default="ocean-insight", metavar="NAME", help="instrument definition")
    c.add_argument("--resource", metavar="SERIAL", help="the spectrometer's serial number (default: the first)")
    c.add_argument("--backend", choices=BACKENDS, help="python-seabreeze backend (default: the definition's)")
    add_area_options(c)
    add_sim_options(c)
    c.add_argument("--integration-ms", type=float, help="integration time [ms] (default: the definition's)")
    c.add_argument(
        "--auto-integration", action="store_true", help="choose the longest integration under 80 %% of full scale"
    )
    c.add_argument("--average", type=int, help="number of spectra averaged")
    c.add_argument(
        "--lamp-spectrum",
        metavar="FILE.txt",
        help="instead of measuring: OceanView export (ASCII with header) of the lamp, in counts",
    )
    c.add_argument(
        "--dark-spectrum", metavar="FILE.txt", help="with --lamp-spectrum: OceanView export of the dark, in counts"
    )
    c.add_argument("--out-cal", metavar="FILE_OOIIrrad.cal", help="write the calibration in Ocean's layout")
    c.add_argument("--out-csv", metavar="FILE.csv", help="write the calibration as wavelength_nm,uJ_per_count")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_calibrate)


def run_calibrate(args) -> int:
    if args.out_cal is None and args.out_csv is None:
        raise ConfigError("out-cal", None, "give --out-cal FILE_OOIIrrad.cal and/or --out-csv FILE.csv")
    for path, key in ((args.out_cal, "--out-cal"), (args.out_csv, "--out-csv")):
        if path is not None:
            output_file(path, key)
    if args.out_cal is not None and args.out_cal == args.out_csv:
        raise ConfigError("out-csv", args.out_csv, "is also --out-cal")
    lamp = read_lamp(args.lamp)
    if (args.lamp_spectrum is None) != (args.dark_spectrum is None):
        raise ConfigError("dark-spectrum", args.dark_spectrum, "--lamp-spectrum and --dark-spectrum go together")
    if args.lamp_spectrum is not None:
        result = _from_exports(args, lamp)
    else:
        result = _measure(args, lamp)
    wavelength_nm, factor = result.pop("wavelength_nm"), result.pop("uj_per_count")
    fibre_um = 2.0 * math.sqrt(result["area_cm2"] / math.pi) * 1e4
    header = {
        "Date": datetime.datetime.now(datetime.UTC).strftime("%a %b %d %H:%M:%S UTC %Y"),
        "Spectrometer": result["serial"],
        "Integration Time (sec)": f"{result['integration_ms'] / 1000.0:.6E}",
        "Fiber (micron)": f"{fibre_um:.1f}",
        "Lamp": args.lamp,
        "Created by": "uwlab spectrometer calibrate",
    }
    if args.out_cal is not None:
        write_ocean_calibration(args.out_cal, wavelength_nm, factor, header)
    if args.out_csv is not None:
        write_calibration_csv(
            args.out_csv,
            wavelength_nm,
            factor,
            [f"{k}: {v}" for k, v in header.items()] + [f"collection area: {result['area_cm2']!r} cm²"],
        )
    summary = {
        **result,
        "fiber_um": fibre_um,
        "out_cal": args.out_cal,
        "out_csv": args.out_csv,
        "wavelength_nm": [float(wavelength_nm[0]), float(wavelength_nm[-1])],
        "uj_per_count_range": [float(factor.min()), float(factor.max())],
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(
            f"calibration: {len(factor)} pixels, {wavelength_nm[0]:g}–{wavelength_nm[-1]:g} nm, "
            f"{factor.min():.4g}–{factor.max():.4g} µJ/count"
        )
        print(
            f"from          {result['source']}, {result['integration_ms']:g} ms, A = {result['area_cm2']:.5g} cm² "
            f"(Fiber (micron) {fibre_um:.1f}), lamp peak {100 * result['peak_fraction']:.1f} % of full scale"
            if result["peak_fraction"] is not None
            else f"from          {result['source']}, {result['integration_ms']:g} ms, A = {result['area_cm2']:.5g} cm²"
        )
        for path in (args.out_cal, args.out_csv):
            if path is not None:
                print(f"wrote         {path}")
    return 0


def _area(args) -> float:
    return collection_area_cm2(
        load_definition(args.instrument).collection_area_cm2, None, args.area_cm2, args.cosine_corrector
    )


def _measure(args, lamp) -> dict:
    """Lamp and dark read on the spectrometer; C on its pixels."""
    if args.integration_ms is not None:
        check_integration_ms(args.integration_ms)
    averaging = None if args.average is None else check_averaging(args.average)
    area = _area(args)
    bench = sim_bench(args)
    if bench is not None and args.sim_lamp is None:
        bench.light_from_table(*lamp)  # the simulated bench is lit by the lamp its file describes
    block, unblock = operator(bench)
    with open_instrument(
        args.instrument,
        args.resource,
        None,
        area,
        backend=args.backend,
        integration_ms=args.integration_ms,
        dark_mode="measured",
        spectrometer_class=None if bench is None else bench.spectrometer_class(),
    ) as spectrometer:
        check_lamp_covers(spectrometer.wavelength_nm, lamp[0], args.lamp)
        if averaging is not None:
            spectrometer.set_averaging(averaging)
        if args.auto_integration:
            spectrometer.auto_integration()
        raw, saturated = spectrometer.read_raw()
        if saturated:
            raise ConfigError(
                "integration_ms",
                spectrometer.integration_ms(),
                "the lamp saturates the spectrometer; lower --integration-ms or use --auto-integration",
            )
        block()
        dark = spectrometer.measure_dark()
        spectrometer.use_dark(dark, "dark")
        unblock()
        signal, saturated = spectrometer.read_counts()
        if saturated:
            raise ConfigError("integration_ms", spectrometer.integration_ms(), "the lamp saturates the spectrometer")
        wavelength_nm = spectrometer.wavelength_nm
        factor = lamp_calibration(
            wavelength_nm,
            signal,
            spectrometer.integration_ms() / 1000.0,
            area,
            lamp,
            spectrometer.electric_dark_pixels,
            args.lamp,
        )
        return {
            "wavelength_nm": wavelength_nm,
            "uj_per_count": factor,
            "source": f"{spectrometer.model} {spectrometer.serial}",
            "serial": spectrometer.serial,
            "integration_ms": spectrometer.integration_ms(),
            "averaging": spectrometer.averaging(),
            "area_cm2": area,
            "peak_fraction": float(np.max(raw) / spectrometer.max_intensity),
        }


def _from_exports(args, lamp) -> dict:
    """Lamp and dark from OceanView exports (counts at one integration time); C on their wavelengths."""
    for name in ("sim", "resource", "integration_ms", "auto_integration", "average", "backend"):
        if getattr(args, name) not in (None, False):
            raise ConfigError(name.replace("_", "-"), getattr(args, name), "not used with --lamp-spectrum")
    lit = read_oceanview_spectrum(args.lamp_spectrum, "lamp-spectrum")
    dark = read_oceanview_spectrum(args.dark_spectrum, "dark-spectrum")
    for export, key, path in ((lit, "lamp-spectrum", args.lamp_spectrum), (dark, "dark-spectrum", args.dark_spectrum)):
        if export.integration_s is None:
            raise ConfigError(key, path, "no Integration Time (sec) or (usec) line in its header")
    assert lit.integration_s is not None and dark.integration_s is not None
    if abs(dark.integration_s / lit.integration_s - 1) > EXPORT_INTEGRATION_MATCH:
        raise ConfigError(
            "dark-spectrum",
            args.dark_spectrum,
            f"taken at {dark.integration_s:g} s, the lamp at {lit.integration_s:g} s; a dark must match the "
            "integration time",
        )
    if lit.wavelength_nm.shape != dark.wavelength_nm.shape or np.any(lit.wavelength_nm != dark.wavelength_nm):
        raise ConfigError("dark-spectrum", args.dark_spectrum, "its wavelengths are not the lamp export's")
    area = _area(args)
    factor = lamp_calibration(lit.wavelength_nm, lit.values - dark.values, lit.integration_s, area, lamp, (), args.lamp)
    serial = lit.header.get("Spectrometer") or lit.header.get("Spectrometers") or "unknown"
    return {
        "wavelength_nm": lit.wavelength_nm,
        "uj_per_count": factor,
        "source": f"{args.lamp_spectrum} less {args.dark_spectrum}",
        "serial": serial,
        "integration_ms": lit.integration_s * 1000.0,
        "averaging": None,
        "area_cm2": area,
        "peak_fraction": None,
    }
