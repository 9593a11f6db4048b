"""`uwlab emva`: EMVA 1288 characterisation of a sweep dataset or a descriptor dataset, and export to the
EMVA 1288 descriptor format."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from uwlab.errors import ConfigError

_SUMMARY = (
    ("K_dn_per_e", "system gain K", "DN/e-", "{:.5g}"),
    ("quantum_efficiency", "quantum efficiency η", "", "{:.4f}"),
    ("dark_noise_e", "temporal dark noise σ_d", "e-", "{:.4g}"),
    ("saturation_e", "saturation capacity μ_e,sat", "e-", "{:.5g}"),
    ("snr_max_db", "maximum SNR", "dB", "{:.2f}"),
    ("dynamic_range_db", "dynamic range", "dB", "{:.2f}"),
    ("linearity_error_percent", "linearity error", "%", "{:.3g}"),
    ("dark_current_e_per_s", "dark current", "e-/s", "{:.4g}"),
    ("dsnu_e", "DSNU", "e-", "{:.3g}"),
    ("prnu_percent", "PRNU", "%", "{:.3g}"),
)


def register(subparsers) -> None:
    p = subparsers.add_parser("emva", description="EMVA 1288 Release 4.0 (linear) characterisation (docs/emva.md).")
    sub = p.add_subparsers(dest="emva_command", required=True, parser_class=type(p))
    c = sub.add_parser("characterize", help="EMVA 1288 parameters, plots and a sensor profile from a photon transfer")
    c.add_argument("dataset", nargs="?", help="uwlab sweep dataset directory")
    c.add_argument("--descriptor", metavar="FILE", help="EMVA 1288 descriptor file (instead of a dataset)")
    _input_options(c)
    c.add_argument("--name", help="name of the sensor profile written to --out (default: measured-<camera>)")
    c.add_argument("--seed", type=int, default=0, help="seed of the emcee posterior (default 0)")
    c.add_argument("--out", metavar="DIR", help="write emva.json, the plots and the profile TOML here")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_characterize)
    e = sub.add_parser("export", help="write a dataset's photon transfer as an EMVA 1288 descriptor dataset")
    e.add_argument("dataset", help="uwlab sweep dataset directory")
    _input_options(e)
    e.add_argument("--out", metavar="DIR", required=True, help="directory for the descriptor and its images")
    e.add_argument("--image-size", default="256x256", metavar="WxH", help="synthetic image size (default 256x256)")
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(func=run_export)


def _input_options(p) -> None:
    p.add_argument("--sweep", help="sweep_id of the photon-transfer sweep (default: the only one)")
    p.add_argument("--irradiance", metavar="W_M2|CSV",
                   help="irradiance at the sensor: a number [W/m²] (with --wavelength-nm) or a spectrum CSV "
                        "(wavelength_nm, irradiance_w_m2_nm); overrides the dataset's readings")
    p.add_argument("--wavelength-nm", type=float, help="wavelength of monochromatic light, for integrated irradiances")
    p.add_argument("--pixel-size-um", type=float, help="pixel pitch (default: from the dataset's sensor profile)")


def _check_inputs(args) -> None:
    """The numeric options through the quantities of `uwlab.model.schema` (plausibility limits included)."""
    from uwlab.model.schema import PixelSizeUm, WavelengthNm, check

    if args.wavelength_nm is not None:
        check(WavelengthNm, args.wavelength_nm, "--wavelength-nm")
    if args.pixel_size_um is not None:
        check(PixelSizeUm, args.pixel_size_um, "--pixel-size-um")


def _override(args):
    from uwlab.experiments.emva.from_dataset import IrradianceOverride
    from uwlab.model.schema import IrradianceWM2, check

    if args.irradiance is None:
        return None
    try:
        value = float(args.irradiance)
    except ValueError:
        return IrradianceOverride.from_csv(args.irradiance)
    return IrradianceOverride(irradiance_w_m2=check(IrradianceWM2, value, "--irradiance"),
                              wavelength_nm=args.wavelength_nm)


def _load_dataset(args):
    from uwlab.experiments.dataset import Dataset
    from uwlab.experiments.emva.from_dataset import (
        named_profile,
        photon_transfer_from_points,
    )

    dataset = Dataset.open(args.dataset)
    points = dataset.points()
    pt = photon_transfer_from_points(points, dataset.spectra(), sweep_id=args.sweep, pixel_size_um=args.pixel_size_um,
                                     override=_override(args), wavelength_nm=args.wavelength_nm,
                                     source=f"dataset {args.dataset}")
    camera = points["camera_model"].dropna() if "camera_model" in points else []
    return pt, named_profile(points), (str(camera.iloc[0]) if len(camera) else "camera")


def run_characterize(args) -> int:
    from uwlab.experiments.emva.analysis import characterize
    from uwlab.experiments.emva.output import output_paths, profile_name, result_document, write_characterization

    if (args.dataset is None) == (args.descriptor is None):
        raise ConfigError("DATASET|--descriptor", None, "give exactly one of a dataset directory or --descriptor")
    _check_inputs(args)
    if args.descriptor:
        from uwlab.experiments.emva.descriptor import photon_transfer_from_descriptor

        pt, base, camera = photon_transfer_from_descriptor(args.descriptor, args.pixel_size_um), None, "descriptor"
    else:
        pt, base, camera = _load_dataset(args)
    name = profile_name(args.name or f"measured-{camera}")
    paths = output_paths(Path(args.out), name, bool(args.pixel_size_um or base)) if args.out else None
    result = characterize(pt, seed=args.seed)
    if paths is not None:
        document = write_characterization(result, pt, paths, name=name, base=base, pixel_size_um=args.pixel_size_um)
    else:
        document = result_document(result)
    if args.json:
        json.dump(document, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(_summary(document))
    return 0


def _summary(doc: dict) -> str:
    lines = [f"EMVA 1288 (Release 4.0 linear) — {doc['source']}",
             f"{doc['points']} points, {doc['sensitivity_fit_points']} in the 0-70 % fit, gain {doc['gain_db']:g} dB, "
             f"{doc['bit_depth']} bit"]
    for key, label, unit, fmt in _SUMMARY:
        value = doc.get(key)
        text = "n/a" if value is None else fmt.format(value)
        std = doc.get(f"{key}_std")
        if value is not None and std is not None:
            text += f" ± {fmt.format(std)}"
            if doc.get(f"{key}_std_mcmc") is not None:
                text += f" (posterior ± {fmt.format(doc[f'{key}_std_mcmc'])})"
        lines.append(f"  {label:<30} {text} {unit}".rstrip())
    lines += [f"  note: {n}" for n in doc.get("notes", [])]
    lines += [f"  wrote {f}" for f in doc.get("files", [])]
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
    from uwlab.experiments.emva.descriptor import write_descriptor

    shape = _image_size(args.image_size)
    _check_inputs(args)
    pt, _, _ = _load_dataset(args)
    path = write_descriptor(pt, args.out, shape=shape, source=pt.source)
    if args.json:
        json.dump({"descriptor": str(path), "points": int(len(pt.photons)), "synthetic_images": True}, sys.stdout)
        sys.stdout.write("\n")
    else:
        print(f"wrote {path} ({len(pt.photons)} points, synthetic images from the recorded statistics)")
    return 0
