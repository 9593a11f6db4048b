"""`uwlab spectrum`: read the spectrometer (or import a Sekonic C-7000 CSV) and derive lux, W/m², photons, CCT.

Sources: ``--port`` (the serial spectrometer, already calibrated), ``--instrument NAME`` (an instrument definition
of ``configs/instruments/``: Ocean Insight through python-seabreeze, raw counts turned into W/m²/nm by the
calibration file — Ocean's ``*_OOIIrrad.cal`` or uwlab's CSV — collection area and dark; ``--raw`` prints the
counts instead; ``--sim`` reads the simulated spectrometer on its bench, `uwlab.sim.devices.ocean_insight`;
docs/spectrometers.md) or ``--import`` (a Sekonic C-7000 CSV).
Every input is checked before a device is opened, and nothing is written unless the reading succeeded.
"""

from __future__ import annotations

import csv
import json
import sys
from collections.abc import Callable

from uwlab.api.instruments import open_spectrometer
from uwlab.drivers.ocean_insight import open_instrument, read_dark, write_dark
from uwlab.drivers.ocean_insight.definition import BACKENDS
from uwlab.drivers.ocean_insight.device import DarkMode, DarkSpectrum
from uwlab.drivers.ocean_insight.files import COSINE_CORRECTOR_DIAMETER_MM, read_lamp
from uwlab.drivers.serial import PROTOCOLS
from uwlab.drivers.serial.base import check_averaging, check_integration_ms
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.spectra import read_sekonic_csv, spectrum_summary, write_spectrum_csv
from uwlab.outputs import output_file

OCEAN_ONLY = (
    "resource",
    "calibration",
    "area_cm2",
    "cosine_corrector",
    "dark",
    "dark_now",
    "save_dark",
    "auto_integration",
    "backend",
    "raw",
    "sim",
    "sim_lamp",
)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "spectrum", description="Spectral irradiance from the spectrometer or a Sekonic C-7000 CSV export."
    )
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--port", help="serial port of the spectrometer")
    source.add_argument("--import", dest="import_path", metavar="FILE.csv", help="Sekonic C-7000 CSV export")
    source.add_argument(
        "--instrument",
        metavar="NAME",
        help="instrument definition in configs/instruments/ "
        "(ocean-insight: an Ocean Insight spectrometer through python-seabreeze)",
    )
    p.add_argument("--protocol", choices=PROTOCOLS, default=PROTOCOLS[0], help="instrument protocol (--port)")
    ocean = p.add_argument_group("--instrument (seabreeze) options")
    ocean.add_argument("--resource", metavar="SERIAL", help="the spectrometer's serial number (default: the first)")
    ocean.add_argument("--backend", choices=BACKENDS, help="python-seabreeze backend (default: the definition's)")
    ocean.add_argument(
        "--calibration",
        metavar="FILE",
        help="absolute irradiance calibration [µJ/count]: OceanView's *_OOIIrrad.cal, or a CSV with columns "
        "wavelength_nm, uJ_per_count",
    )
    add_area_options(ocean)
    ocean.add_argument(
        "--raw", action="store_true", help="print the raw counts per pixel (no dark, no correction, no calibration)"
    )
    add_sim_options(ocean)
    dark = ocean.add_mutually_exclusive_group()
    dark.add_argument(
        "--dark",
        metavar="FILE.csv",
        help="dark spectrum at the same integration time (default: the device's electric-dark pixels)",
    )
    dark.add_argument("--dark-now", action="store_true", help="measure the dark first (asks you to block the light)")
    ocean.add_argument("--save-dark", metavar="FILE.csv", help="with --dark-now: keep the dark for --dark")
    ocean.add_argument(
        "--auto-integration", action="store_true", help="choose the longest integration under 80 %% of full scale"
    )
    p.add_argument("--integration-ms", type=float, help="integration time [ms]")
    p.add_argument("--average", type=int, help="number of spectra averaged")
    p.add_argument("--out", metavar="FILE.csv", help="write wavelength_nm,irradiance_w_m2_nm (never overwritten)")
    p.add_argument(
        "--json",
        action="store_true",
        help='print one JSON object (with "saturated": whether the spectrometer saturated; null for an import)',
    )
    p.set_defaults(func=run)


def add_area_options(group) -> None:
    """``--area-cm2`` and ``--cosine-corrector`` (`uwlab.drivers.ocean_insight.device.collection_area_cm2`)."""
    group.add_argument(
        "--area-cm2",
        type=float,
        help="collection area of the cosine corrector or fibre [cm²] (default: the calibration file's Fiber "
        "(micron), else the definition's)",
    )
    group.add_argument(
        "--cosine-corrector",
        metavar="NAME",
        help=f"the cosine corrector on the fibre, for its diffuser's area ({', '.join(COSINE_CORRECTOR_DIAMETER_MM)})",
    )


def add_sim_options(group) -> None:
    group.add_argument(
        "--sim",
        action="store_true",
        help="the simulated Ocean Insight spectrometer (a Flame on a bench lit by a 3100 K calibration lamp)",
    )
    group.add_argument(
        "--sim-lamp", metavar="FILE.LMP", help="with --sim: light the simulated bench with this lamp file instead"
    )


def sim_bench(args):
    """The simulated bench of ``--sim`` (lit by ``--sim-lamp`` when given), or None."""
    if not args.sim:
        if args.sim_lamp is not None:
            raise ConfigError("sim-lamp", args.sim_lamp, "needs --sim")
        return None
    from uwlab.sim.devices.ocean_insight import SimBench

    bench = SimBench()
    if args.sim_lamp is not None:
        bench.light_from_table(*read_lamp(args.sim_lamp, "sim-lamp"))
    return bench


def operator(bench) -> tuple[Callable[[], None], Callable[[], None]]:
    """(block the light, unblock it): the simulated bench does it itself; a real bench asks the operator."""
    if bench is not None:
        return bench.block, bench.unblock
    return (lambda: _confirm("block the light to the spectrometer")), (lambda: _confirm("unblock the light"))


def run(args) -> int:
    if args.out is not None:
        output_file(args.out, "--out")
    if args.instrument is None:
        given = [name for name in OCEAN_ONLY if getattr(args, name) not in (None, False)]
        if given:
            raise ConfigError(given[0].replace("_", "-"), getattr(args, given[0]), "needs --instrument")
    if args.save_dark is not None:
        output_file(args.save_dark, "--save-dark")
    details: dict[str, object] = {}
    dark = None
    if args.import_path is not None:
        if args.integration_ms is not None or args.average is not None:
            raise ConfigError("import", args.import_path, "--integration-ms and --average need --port")
        (wavelength_nm, irradiance), saturated = read_sekonic_csv(args.import_path), None
    elif args.instrument is not None and args.raw:
        return _raw_ocean(args)
    elif args.instrument is not None:
        (wavelength_nm, irradiance), saturated, details, dark = _measure_ocean(args)
    else:
        (wavelength_nm, irradiance), saturated = _measure(args)
    summary = {**spectrum_summary(wavelength_nm, irradiance), "saturated": saturated, **details}
    if args.out is not None:
        write_spectrum_csv(args.out, wavelength_nm, irradiance)
    if args.save_dark is not None and dark is not None:
        write_dark(args.save_dark, dark)
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


def _confirm(message: str) -> None:
    """Ask the operator on stderr (stdout may carry the JSON) and wait for Enter; 'q' stops."""
    print(f"{message}, then press Enter (or type 'q' to stop): ", end="", file=sys.stderr, flush=True)
    reply = sys.stdin.readline()
    if reply.strip().lower() in ("q", "quit") or not reply:
        raise ConfigError("operator", reply.strip() or "end of input", "stopped at the prompt")


def _measure_ocean(args) -> tuple[tuple, bool, dict[str, object], DarkSpectrum | None]:
    """((wavelength_nm, irradiance_w_m2_nm), saturated, what the reading used, the dark measured now or None)
    from a seabreeze spectrometer; every file and value is checked before the device is opened."""
    if args.save_dark is not None and not args.dark_now:
        raise ConfigError("save-dark", args.save_dark, "needs --dark-now")
    if args.integration_ms is not None:
        check_integration_ms(args.integration_ms)
    averaging = None if args.average is None else check_averaging(args.average)
    dark_file = None if args.dark is None else read_dark(args.dark)
    if dark_file is not None and args.auto_integration:
        raise ConfigError(
            "dark", args.dark, "a dark file fixes the integration time; use --dark-now with --auto-integration"
        )
    dark_mode: DarkMode = "electric" if dark_file is None and not args.dark_now else "measured"
    if args.calibration is None:
        raise ConfigError(
            "calibration",
            None,
            f"{args.instrument} needs a calibration file (*_OOIIrrad.cal, or CSV wavelength_nm,uJ_per_count) or --raw",
        )
    bench = sim_bench(args)
    block, unblock = operator(bench)
    with open_instrument(
        args.instrument,
        args.resource,
        args.calibration,
        args.area_cm2,
        cosine_corrector=args.cosine_corrector,
        backend=args.backend,
        integration_ms=args.integration_ms,
        dark_mode=dark_mode,
        spectrometer_class=None if bench is None else bench.spectrometer_class(),
    ) as spectrometer:
        if averaging is not None:
            spectrometer.set_averaging(averaging)
        if args.auto_integration:
            spectrometer.auto_integration()
        dark = None
        if dark_file is not None:
            spectrometer.use_dark(dark_file, args.dark)
        elif args.dark_now:
            block()
            dark = spectrometer.measure_dark()
            spectrometer.use_dark(dark, "--dark-now")
            unblock()
        spectrum = spectrometer.read_spectrum()
        details = {
            "integration_ms": spectrometer.integration_ms(),
            "averaging": spectrometer.averaging(),
            "serial": spectrometer.serial,
            "model": spectrometer.model,
            "dark": spectrometer.dark_mode,
            "nonlinearity_corrected": spectrometer.nonlinearity_corrected,
            "area_cm2": spectrometer.area_cm2,
            "calibration": args.calibration,
        }
        return spectrum, spectrometer.last_saturated, details, dark


def _raw_ocean(args) -> int:
    """``--raw``: the raw counts per pixel, averaged (no electric dark, nonlinearity, dark or calibration)."""
    for name in ("calibration", "dark", "dark_now", "save_dark", "area_cm2", "cosine_corrector"):
        if getattr(args, name) is not None and getattr(args, name) is not False:  # 0.0 == False: given, refused
            raise ConfigError(name.replace("_", "-"), getattr(args, name), "not used with --raw (counts only)")
    if args.integration_ms is not None:
        check_integration_ms(args.integration_ms)
    averaging = None if args.average is None else check_averaging(args.average)
    bench = sim_bench(args)
    with open_instrument(
        args.instrument,
        args.resource,
        None,
        backend=args.backend,
        integration_ms=args.integration_ms,
        dark_mode="none",
        spectrometer_class=None if bench is None else bench.spectrometer_class(),
    ) as spectrometer:
        if averaging is not None:
            spectrometer.set_averaging(averaging)
        if args.auto_integration:
            spectrometer.auto_integration()
        counts, saturated = spectrometer.read_raw()
        reading = {
            "wavelength_nm": spectrometer.wavelength_nm.tolist(),
            "counts": counts.tolist(),
            "saturated": saturated,
            "max_intensity": spectrometer.max_intensity,
            "integration_ms": spectrometer.integration_ms(),
            "averaging": spectrometer.averaging(),
            "serial": spectrometer.serial,
            "model": spectrometer.model,
        }
    if args.out is not None:
        try:
            with open(args.out, "x", newline="") as fh:
                writer = csv.writer(fh)
                writer.writerow(("wavelength_nm", "counts"))
                writer.writerows(
                    (repr(w), repr(c)) for w, c in zip(reading["wavelength_nm"], reading["counts"], strict=True)
                )
        except FileExistsError:
            raise ConfigError("out", args.out, "file exists; refusing to overwrite it") from None
        except OSError as exc:
            raise ConfigError("out", args.out, f"cannot write ({exc.strerror})") from None
    if args.json:
        print(json.dumps(reading))
    else:
        peak = max(range(len(counts)), key=lambda i: counts[i])
        print(f"raw counts: {len(counts)} pixels, {reading['wavelength_nm'][0]:g}–{reading['wavelength_nm'][-1]:g} nm")
        print(
            f"peak            {counts[peak]:.6g} counts at {reading['wavelength_nm'][peak]:g} nm "
            f"({100 * counts[peak] / spectrometer.max_intensity:.1f} % of full scale {spectrometer.max_intensity:g})"
        )
        print(f"lowest          {counts.min():.6g} counts")
        print(
            f"spectrometer    {reading['model']} {reading['serial']}, {reading['integration_ms']:g} ms x "
            f"{reading['averaging']}"
        )
        if saturated:
            print("saturated       yes: the readings are clipped; reduce --integration-ms (or --auto-integration)")
    return 0


def _print_summary(summary: dict) -> None:
    wavelength_nm = summary["wavelength_nm"]
    cct = summary["cct_k"]
    print(f"spectrum: {len(wavelength_nm)} samples, {wavelength_nm[0]:g}–{wavelength_nm[-1]:g} nm")
    print(f"irradiance      {summary['irradiance_w_m2']:.6g} W/m²")
    print(f"illuminance     {summary['illuminance_lux']:.6g} lx")
    print(f"photon flux     {summary['photon_flux_m2_s']:.6g} m⁻² s⁻¹")
    print(f"CCT             {'undefined' if cct is None else f'{cct:.0f} K'}")
    if summary["saturated"]:
        print("saturated       yes: the readings are clipped; reduce --integration-ms (or --auto-integration)")
    if "serial" in summary:
        print(
            f"spectrometer    {summary['model']} {summary['serial']}, {summary['integration_ms']:g} ms x "
            f"{summary['averaging']}, dark {summary['dark']}, nonlinearity "
            f"{'corrected' if summary['nonlinearity_corrected'] else 'not corrected'}, "
            f"A = {summary['area_cm2']:g} cm²"
        )
