"""`uwlab spectrometer calibrate`: OceanView's irradiance calibration of an Ocean Insight spectrometer against a
calibration lamp's ``.LMP`` file, written in Ocean's ``OOIIrrad.cal`` layout and uwlab's CSV (docs/spectrometers.md).

The lamp and a dark (light blocked) are read at one integration time — measured on the spectrometer (``--sim``:
the simulated one, lit by the lamp the file describes), or taken from two OceanView exports
(``--lamp-spectrum``, ``--dark-spectrum``) — and

    C(λ) [µJ/count] = E_lamp(λ) [µW/cm²/nm] · T [s] · A [cm²] · dλ [nm] / (S(λ) − D(λ)) [counts]

(`uwlab.experiments.acquisition.spectrometer_calibration`). Every input and output path is checked before the
device is opened; nothing is written unless the calibration succeeded, and no file is ever replaced.
"""

from __future__ import annotations

import json

from uwlab.cli.spectrum import add_area_options, add_sim_options, operator, sim_bench
from uwlab.drivers.ocean_insight import open_instrument
from uwlab.drivers.ocean_insight.definition import BACKENDS, load_definition
from uwlab.drivers.ocean_insight.device import collection_area_cm2
from uwlab.drivers.ocean_insight.files import read_lamp
from uwlab.drivers.serial.base import check_averaging, check_integration_ms
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.spectrometer_calibration import (
    LampCalibration,
    lamp_calibration_from_exports,
    measure_lamp_calibration,
)
from uwlab.outputs import output_file


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
    area = collection_area_cm2(
        load_definition(args.instrument).collection_area_cm2, None, args.area_cm2, args.cosine_corrector
    )
    if args.lamp_spectrum is not None:
        for name in ("sim", "resource", "integration_ms", "auto_integration", "average", "backend"):
            if getattr(args, name) not in (None, False):
                raise ConfigError(name.replace("_", "-"), getattr(args, name), "not used with --lamp-spectrum")
        result = lamp_calibration_from_exports(args.lamp_spectrum, args.dark_spectrum, lamp, args.lamp, area)
    else:
        result = _measure(args, lamp, area)
    result.write(args.out_cal, args.out_csv, args.lamp)
    summary = {
        "serial": result.serial,
        "source": result.source,
        "integration_ms": result.integration_ms,
        "averaging": result.averaging,
        "area_cm2": result.area_cm2,
        "fiber_um": result.fiber_um,
        "peak_fraction": result.peak_fraction,
        "out_cal": args.out_cal,
        "out_csv": args.out_csv,
        "wavelength_nm": [float(result.wavelength_nm[0]), float(result.wavelength_nm[-1])],
        "uj_per_count_range": [float(result.uj_per_count.min()), float(result.uj_per_count.max())],
    }
    if args.json:
        print(json.dumps(summary))
        return 0
    wavelength_nm, factor = result.wavelength_nm, result.uj_per_count
    print(
        f"calibration: {len(factor)} pixels, {wavelength_nm[0]:g}–{wavelength_nm[-1]:g} nm, "
        f"{factor.min():.4g}–{factor.max():.4g} µJ/count"
    )
    peak = "" if result.peak_fraction is None else f", lamp peak {100 * result.peak_fraction:.1f} % of full scale"
    print(
        f"from          {result.source}, {result.integration_ms:g} ms, A = {result.area_cm2:.5g} cm² "
        f"(Fiber (micron) {result.fiber_um:.1f}){peak}"
    )
    for path in (args.out_cal, args.out_csv):
        if path is not None:
            print(f"wrote         {path}")
    return 0


def _measure(args, lamp, area_cm2: float) -> LampCalibration:
    """Lamp and dark read on the spectrometer (every value checked before it is opened)."""
    if args.integration_ms is not None:
        check_integration_ms(args.integration_ms)
    averaging = None if args.average is None else check_averaging(args.average)
    bench = sim_bench(args)
    if bench is not None and args.sim_lamp is None:
        bench.light_from_table(*lamp)  # the simulated bench is lit by the lamp its file describes
    block, unblock = operator(bench)
    with open_instrument(
        args.instrument,
        args.resource,
        None,
        area_cm2,
        backend=args.backend,
        integration_ms=args.integration_ms,
        dark_mode="measured",
        spectrometer_class=None if bench is None else bench.spectrometer_class(),
    ) as spectrometer:
        if averaging is not None:
            spectrometer.set_averaging(averaging)
        return measure_lamp_calibration(
            spectrometer, lamp, args.lamp, block, unblock, auto_integration=args.auto_integration
        )
