"""`uwlab emva`: EMVA 1288 Release 4.0 characterisation of a sweep dataset, a descriptor dataset or a fleet of them,
and export to the EMVA 1288 descriptor format."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from typing import TYPE_CHECKING

from uwlab.errors import ConfigError

if TYPE_CHECKING:
    from uwlab.experiments.emva.datasheet import SheetInfo
    from uwlab.experiments.emva.output import OutputPaths
    from uwlab.experiments.emva.transfer import PhotonTransfer
    from uwlab.model.sensor import SensorProfile

_SUMMARY = (
    ("K_dn_per_e", "system gain K", "DN/e-", "{:.5g}"),
    ("quantum_efficiency", "quantum efficiency η", "", "{:.4f}"),
    ("responsivity_dark_dn_per_photon", "responsivity in the dark R_d", "DN/p", "{:.4g}"),
    ("dark_noise_e", "temporal dark noise σ_d", "e-", "{:.4g}"),
    ("dark_noise_p", "temporal dark noise σ_d", "p", "{:.4g}"),
    ("dark_noise_dn", "temporal dark noise σ_y.dark", "DN", "{:.4g}"),
    ("saturation_e", "saturation capacity μ_e.sat", "e-", "{:.5g}"),
    ("saturation_photons", "saturation μ_p.sat", "p", "{:.5g}"),
    ("sensitivity_threshold_photons", "sensitivity threshold μ_p.min", "p", "{:.4g}"),
    ("snr_max_db", "maximum SNR", "dB", "{:.2f}"),
    ("dynamic_range_db", "dynamic range", "dB", "{:.2f}"),
    ("linearity_error_percent", "linearity error LE", "%", "{:.3g}"),
    ("dark_current_e_per_s", "dark current", "e-/s", "{:.4g}"),
    ("dark_current_p_per_s", "dark current", "p/s", "{:.4g}"),
    ("dsnu_e", "DSNU1288", "e-", "{:.3g}"),
    ("dsnu_p", "DSNU1288", "p", "{:.3g}"),
    ("prnu_percent", "PRNU1288", "%", "{:.3g}"),
)
_FLEET_COLUMNS = (
    ("K_dn_per_e", "K DN/e-", "{:.4g}"),
    ("quantum_efficiency", "η", "{:.3f}"),
    ("dark_noise_e", "σ_d e-", "{:.3g}"),
    ("saturation_e", "μe.sat e-", "{:.5g}"),
    ("dynamic_range_db", "DR dB", "{:.1f}"),
    ("linearity_error_percent", "LE %", "{:.2g}"),
    ("dsnu_e", "DSNU e-", "{:.3g}"),
    ("prnu_percent", "PRNU %", "{:.3g}"),
    ("dark_current_e_per_s", "Idark e-/s", "{:.3g}"),
)
MODELS = ("linear", "general")
MISSING = "—"  # a figure the measurement does not give; the reason is printed beside it or under the table


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "emva", description="EMVA 1288 Release 4.0 (linear or general model) characterisation (docs/emva.md)."
    )
    sub = p.add_subparsers(dest="emva_command", required=True, parser_class=type(p))
    c = sub.add_parser("characterize", help="EMVA 1288 parameters, datasheet, XML and a sensor profile")
    c.add_argument("dataset", nargs="?", help="uwlab sweep dataset directory")
    c.add_argument("--descriptor", metavar="FILE", help="EMVA 1288 descriptor file (instead of a dataset)")
    _input_options(c)
    _channel_option(c, "characterise only this colour channel of a raw Bayer sweep (default: each of the three)")
    _model_option(c)
    c.add_argument("--name", help="name of the sensor profile written to --out (default: measured-<camera>)")
    c.add_argument(
        "--out",
        metavar="DIR",
        help="write emva.json, datasheet.html, emva1288.xml, the figures and the profile TOML here (a colour sweep "
        "without --channel: one sub-directory per channel, DIR/red, DIR/green, DIR/blue, and DIR/channels.json)",
    )
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_characterize)
    f = sub.add_parser("fleet", help="characterise every dataset and descriptor under a folder (one row per camera)")
    f.add_argument("folder", help="folder holding datasets and/or EMVA1288*.txt descriptor files")
    _model_option(f)
    f.add_argument(
        "--pixel-size-um", type=float, help="pixel pitch for descriptors (datasets use their sensor profile)"
    )
    f.add_argument("--out", metavar="DIR", help="one sub-directory per camera, plus fleet.csv and fleet.json")
    f.add_argument(
        "--dask",
        metavar="ADDRESS",
        help="the cameras in parallel on a Dask cluster: local (one worker per core) or tcp://HOST:PORT",
    )
    f.add_argument("--json", action="store_true", help="print the rows as a JSON list")
    f.set_defaults(func=run_fleet)
    e = sub.add_parser(
        "export",
        help="write a dataset's photon transfer as an EMVA 1288 descriptor dataset (its "
        "recorded frames, else synthetic images)",
    )
    e.add_argument("dataset", help="uwlab sweep dataset directory")
    _input_options(e)
    _channel_option(e, "the colour channel of a raw Bayer sweep to export (required for one)")
    e.add_argument("--out", metavar="DIR", required=True, help="directory for the descriptor and its images")
    e.add_argument(
        "--image-size",
        default="256x256",
        metavar="WxH",
        help="size of synthetic images when the sweep kept no raw frames (default 256x256)",
    )
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(func=run_export)


def _model_option(p) -> None:
    p.add_argument(
        "--model",
        choices=MODELS,
        default="linear",
        help="Release 4.0 Linear (default) or General (non-linear cameras; suggested by the linear "
        "characterisation when the camera is not linear)",
    )


def _channel_option(p, text: str) -> None:
    p.add_argument(
        "--channel",
        choices=("red", "green", "blue"),
        help=f"{text}; each channel is a sensor of its own (EMVA 1288 Release 4.0 Linear §1.2)",
    )


def _input_options(p) -> None:
    p.add_argument("--sweep", help="sweep_id of the photon-transfer sweep (default: the only one)")
    p.add_argument(
        "--irradiance",
        metavar="W_M2|CSV",
        help="irradiance at the sensor plane: a number [W/m²] (with --wavelength-nm) or a spectrum CSV "
        "(wavelength_nm, irradiance_w_m2_nm); overrides the dataset's readings",
    )
    p.add_argument("--wavelength-nm", type=float, help="wavelength of monochromatic light, for integrated irradiances")
    p.add_argument("--pixel-size-um", type=float, help="pixel pitch (default: from the dataset's sensor profile)")


def _check_inputs(args) -> None:
    """The numeric options through the quantities of `uwlab.model.schema` (plausibility limits included)."""
    if args.wavelength_nm is None and args.pixel_size_um is None:
        return
    from uwlab.model.schema import PixelSizeUm, WavelengthNm, check

    if args.wavelength_nm is not None:
        check(WavelengthNm, args.wavelength_nm, "--wavelength-nm")
    if args.pixel_size_um is not None:
        check(PixelSizeUm, args.pixel_size_um, "--pixel-size-um")


def _check_out(out: str | None) -> None:
    """An output directory checked before anything is computed (`uwlab.outputs.output_dir`)."""
    if out is not None:
        from uwlab.outputs import output_dir

        output_dir(out, "--out")


def _override(args):
    from uwlab.experiments.emva.from_dataset import IrradianceOverride

    return IrradianceOverride.given(args.irradiance, args.wavelength_nm)


def _dataset_options(args) -> dict:
    return {
        "sweep_id": args.sweep,
        "pixel_size_um": args.pixel_size_um,
        "override": _override(args),
        "wavelength_nm": args.wavelength_nm,
        "channel": args.channel,
    }


def _load_dataset(args):
    from uwlab.experiments.emva.from_dataset import load_dataset_input

    return load_dataset_input(args.dataset, **_dataset_options(args))


def _blas_single_threaded() -> None:
    """OpenBLAS's thread pool kept to one thread for this process (and its workers) unless the environment sets one
    (OPENBLAS_NUM_THREADS): the EMVA analysis's only BLAS calls are 3-parameter fits, while starting the pool's
    threads when numpy loads costs 30–50 ms of CPU, a seventh of a small descriptor's characterisation (issue 33).
    Only before numpy is loaded (OpenBLAS reads it then); results are unchanged."""
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def run_characterize(args) -> int:
    _blas_single_threaded()
    from uwlab.experiments.emva.analysis import characterize
    from uwlab.experiments.emva.output import output_paths, profile_name, result_document, write_characterization

    if (args.dataset is None) == (args.descriptor is None):
        raise ConfigError("DATASET|--descriptor", None, "give exactly one of a dataset directory or --descriptor")
    _check_inputs(args)
    _check_out(args.out)
    jobs: dict[str | None, tuple[PhotonTransfer, SensorProfile | None, str, SheetInfo]]
    if args.descriptor:
        from uwlab.experiments.emva.descriptor import parse_descriptor, photon_transfer_from_descriptor, sheet_info

        if args.channel:
            raise ConfigError("--channel", args.channel, "a descriptor holds one sensor: --channel is for a dataset")
        pt = photon_transfer_from_descriptor(args.descriptor, args.pixel_size_um)
        info = sheet_info(parse_descriptor(args.descriptor))
        jobs = {None: (pt, None, info.model if info.model != "—" else "descriptor", info)}
    else:
        from uwlab.experiments.emva.from_dataset import load_dataset_inputs

        loaded = load_dataset_inputs(args.dataset, **_dataset_options(args))
        jobs = {channel: (one.transfer, one.profile, one.camera, one.info) for channel, one in loaded.items()}
    split = len(jobs) > 1  # every channel of a colour sweep, each a sensor of its own
    results = {channel: characterize(job[0], args.model) for channel, job in jobs.items()}
    documents: dict[str | None, dict] = {}
    if args.out:
        if split:
            _make_dir(Path(args.out))
        targets: dict[str | None, tuple[str, OutputPaths]] = {}
        for channel, (_, base, camera, _) in jobs.items():
            name = profile_name(f"{args.name}-{channel}" if args.name and split else args.name or f"measured-{camera}")
            out = Path(args.out) / channel if split and channel else Path(args.out)
            targets[channel] = (name, output_paths(out, results[channel], name, bool(args.pixel_size_um or base)))
        summary = Path(args.out) / CHANNELS_FILE
        if split and summary.exists():
            raise ConfigError("--out", str(summary), "exists; refusing to overwrite")
        for channel, (pt, base, _, info) in jobs.items():
            name, paths = targets[channel]
            documents[channel] = write_characterization(
                results[channel], pt, paths, name=name, base=base, pixel_size_um=args.pixel_size_um, info=info
            )
        if split:
            from uwlab.jsonable import dumps

            summary.write_text(dumps(_channels_document(documents), indent=2) + "\n")
    else:
        documents = {channel: result_document(result) for channel, result in results.items()}
    if not split:
        document = next(iter(documents.values()))
        if args.json:
            json.dump(document, sys.stdout, indent=2)
            sys.stdout.write("\n")
        else:
            print(_summary(document))
        return 0
    if args.json:
        from uwlab.jsonable import dumps

        sys.stdout.write(dumps({**_channels_document(documents), "documents": documents}, indent=2) + "\n")
    else:
        print(_channels_summary(documents, Path(args.out) / CHANNELS_FILE if args.out else None))
    return 0


CHANNELS_FILE = "channels.json"


def _make_dir(out: Path) -> None:
    """The directory holding a colour sweep's per-channel sub-directories (checked by `_check_out`)."""
    try:
        out.mkdir(exist_ok=True)
    except OSError as exc:
        raise ConfigError("--out", str(out), f"cannot create ({exc.strerror or exc})") from None


def _channels_document(documents: dict) -> dict:
    """The per-channel summary of a colour sweep (``channels.json``): the table's figures of each channel."""
    first = next(iter(documents.values()))
    return {
        "standard": first["standard"],
        "source": first["source"].rsplit(",", 1)[0],
        "channels": {
            channel: {key: doc.get(key) for key, _, _ in _FLEET_COLUMNS} | {"wavelength_nm": doc.get("wavelength_nm")}
            for channel, doc in documents.items()
        },
    }


def _channels_summary(documents: dict, summary: Path | None) -> str:
    """Each colour channel's figures, one row each, then the files written."""
    from uwlab.experiments.emva.datasheet import missing_figures

    first = next(iter(documents.values()))
    header = ["channel", *(label for _, label, _ in _FLEET_COLUMNS)]
    rows = [
        [channel, *(MISSING if doc.get(key) is None else fmt.format(doc[key]) for key, _, fmt in _FLEET_COLUMNS)]
        for channel, doc in documents.items()
    ]
    lines = [
        f"EMVA 1288 ({first['standard']}) — {first['source'].rsplit(',', 1)[0]}: each colour channel a sensor of "
        "its own (Release 4.0 Linear §1.2)",
        *_aligned([header, *rows]),
        *_missing_lines({channel: missing_figures(doc) for channel, doc in documents.items()}),
    ]
    notes = {channel: doc.get("notes", []) for channel, doc in documents.items()}
    shared = [n for n in notes[next(iter(notes))] if all(n in other for other in notes.values())]
    lines += [f"  note: {n}" for n in shared]
    lines += [f"  note ({c}): {n}" for c, some in notes.items() for n in some if n not in shared]
    if summary is not None:
        lines += [f"  wrote {Path(doc['files'][0]).parent}/ ({channel})" for channel, doc in documents.items()]
        lines.append(f"  wrote {summary}")
    return "\n".join(lines)


def _missing_lines(missing: dict[str, dict[str, str]]) -> list[str]:
    """Under a table, why its DSNU and PRNU cells are `MISSING`: one line per reason, naming the columns and the
    rows (channels or cameras) it holds for (`uwlab.experiments.emva.datasheet.missing_figures`)."""
    labels = {key: label for key, label, _ in _FLEET_COLUMNS}
    grouped: dict[str, tuple[dict[str, None], dict[str, None]]] = {}
    for row, reasons in missing.items():
        for key, reason in reasons.items():
            columns, rows = grouped.setdefault(reason, ({}, {}))
            columns[labels.get(key, key)] = None
            rows[row] = None
    return [
        f"  {MISSING} {', '.join(columns)} ({', '.join(rows)}): {reason}" for reason, (columns, rows) in grouped.items()
    ]


def _aligned(rows: list[list[str]]) -> list[str]:
    """Rows of cells as text columns: the first left-aligned, the others right-aligned."""
    widths = [max(len(str(r[i])) for r in rows) for i in range(len(rows[0]))]
    return [
        "  ".join(str(c).rjust(w) if i else str(c).ljust(w) for i, (c, w) in enumerate(zip(r, widths, strict=True)))
        for r in rows
    ]


def _summary(doc: dict) -> str:
    from uwlab.experiments.emva.datasheet import missing_figures

    lines = [
        f"EMVA 1288 ({doc['standard']}) — {doc['source']}",
        f"{doc['points']} points, saturation at point {doc['saturation_index']} ({doc['saturation_rule']}), "
        f"gain {doc['gain_db']:g} dB, {doc['bit_depth']} bit",
    ]
    missing = missing_figures(doc)
    for key, label, unit, fmt in _SUMMARY:
        if key not in doc:
            continue
        value = doc[key]
        if value is None:
            lines.append(f"  {label:<32} {MISSING} ({missing[key]})" if key in missing else f"  {label:<32} n/a")
            continue
        text = fmt.format(value)
        std = doc.get(f"{key}_std")
        if std is not None:
            text += f" ± {fmt.format(std)}"
        lines.append(f"  {label:<32} {text} {unit}".rstrip())
    lines += [f"  note: {n}" for n in doc.get("notes", [])]
    lines += [f"  wrote {f}" for f in doc.get("files", [])]
    return "\n".join(lines)


def run_fleet(args) -> int:
    _blas_single_threaded()
    from uwlab.experiments.emva.fleet import characterize_fleet, find_inputs
    from uwlab.model.schema import PixelSizeUm, check

    if args.pixel_size_um is not None:
        check(PixelSizeUm, args.pixel_size_um, "--pixel-size-um")
    _check_out(args.out)
    inputs = find_inputs(args.folder)
    from uwlab.progress import bar

    with bar(total=len(inputs), desc="EMVA 1288", unit="camera") as shown:

        def progress(row) -> None:
            shown.update(1)
            shown.set_postfix_str(row.camera[:30])

        rows = characterize_fleet(
            inputs,
            model=args.model,
            pixel_size_um=args.pixel_size_um,
            out=Path(args.out) if args.out else None,
            progress=progress,
            dask=args.dask,
        )
    documents = [row.document() for row in rows]
    if args.json:
        from uwlab.jsonable import dumps

        sys.stdout.write(dumps(documents, indent=2) + "\n")
    else:
        print(_fleet_table(documents))
    return 0


def _fleet_table(documents: list[dict]) -> str:
    header = ["camera", *(label for _, label, _ in _FLEET_COLUMNS), "status"]
    rows = []
    for doc in documents:
        cells = [doc["camera"]]
        cells += [MISSING if doc.get(key) is None else fmt.format(doc[key]) for key, _, fmt in _FLEET_COLUMNS]
        cells.append("ok" if doc["error"] is None else f"refused: {doc['error']}")
        rows.append(cells)
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header) - 1)]
    lines = []
    for r in [header, *rows]:
        texts = (str(c).rjust(w) if i else str(c).ljust(w) for i, (c, w) in enumerate(zip(r, widths, strict=False)))
        lines.append("  ".join(texts) + "  " + str(r[-1]))
    lines += _missing_lines({doc["camera"]: doc.get("missing") or {} for doc in documents})
    ok = sum(d["error"] is None for d in documents)
    lines.append(f"{ok} of {len(documents)} cameras characterised")
    return "\n".join(lines)


def _image_size(text: str) -> tuple[int, int]:
    width, x, height = text.lower().partition("x")
    try:
        w, h = int(width), int(height)
    except ValueError:
        raise ConfigError("--image-size", text, "expected WxH, e.g. 256x256") from None
    if not x or not (8 <= w <= 8192 and 8 <= h <= 8192):
        raise ConfigError("--image-size", text, "expected WxH with 8 <= W, H <= 8192")
    return h, w


def run_export(args) -> int:
    from uwlab.experiments.dataset import Dataset
    from uwlab.experiments.emva.export import has_recorded_frames, write_descriptor, write_descriptor_from_frames
    from uwlab.experiments.emva.from_dataset import dark_rows

    shape = _image_size(args.image_size)
    _check_inputs(args)
    _check_out(args.out)
    pt = _load_dataset(args).transfer
    dataset = Dataset.open(args.dataset)
    recorded = pt.channel is None and has_recorded_frames(dataset, pt)  # a channel's sites are no frame of their own
    if recorded:
        points = dataset.points()
        darks = dark_rows(points, points[(points["sweep_id"] == pt.sweep_id)])
        dark_points = [(r.sweep_id, r.point_index, r.exposure_us * 1e-6) for r in darks.itertuples()]
        path = write_descriptor_from_frames(dataset, pt, args.out, dark_points=dark_points, source=pt.source)
        how = "the recorded frames"
    else:
        path = write_descriptor(pt, args.out, shape=shape, source=pt.source)
        how = (
            f"SYNTHETIC images from the {pt.channel} channel's recorded statistics"
            if pt.channel
            else "SYNTHETIC images from the recorded statistics: the sweep kept no raw frames (save_frames = true)"
        )
    if args.json:
        json.dump(
            {"descriptor": str(path), "points": int(len(pt.photons)), "synthetic_images": not recorded}, sys.stdout
        )
        sys.stdout.write("\n")
    else:
        print(f"wrote {path} ({len(pt.photons)} points, {how})")
    return 0
