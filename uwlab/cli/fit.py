"""`uwlab fit`: Bayesian calibration of the model against a dataset, with validation."""

from __future__ import annotations

import json
import sys
from uwlab.progress import tau_bar


def register(subparsers) -> None:
    p = subparsers.add_parser("fit", description="Fit the image-formation model's free parameters to a sweep dataset.")
    p.add_argument("dataset", help="dataset directory (from `uwlab sweep`)")
    p.add_argument(
        "--config",
        metavar="FIT.toml",
        help="free parameters and priors (default: light efficiency, attenuation scale, each camera's K, each lens "
        "setting's transmittance, the bare sensors' factor, discrepancies; see configs/fit/default.toml)",
    )
    p.add_argument("--out", metavar="DIR", help="output directory (default: DATASET/fit)")
    p.add_argument(
        "--train",
        action="append",
        metavar="SWEEP_ID",
        help="sweeps the held-out check fits (it predicts the others; default: --held-out)",
    )
    p.add_argument(
        "--held-out",
        type=lambda value: int(value) if value.isdigit() else value,
        metavar="loo|N",
        help="folds of the held-out check: loo, each configuration predicted from a fit of all the others, or N "
        "folds of the sweeps dealt out in order (default: the fit config's [holdout], else loo)",
    )
    p.add_argument(
        "--dask",
        metavar="ADDRESS",
        help="fit the held-out folds on a Dask cluster: local (one worker per core) or tcp://HOST:PORT (default: "
        "worker processes on this machine's cores)",
    )
    p.add_argument(
        "--model",
        choices=("paper", "extended"),
        help="the chain to fit: the paper's or the extended one (default: the dataset's rigs' [model] kind)",
    )
    p.add_argument(
        "--sensor",
        action="append",
        metavar="[CAMERA=]FROM",
        help="use the camera as characterised by `uwlab emva characterize` (FROM: its profile TOML or output "
        "folder): its measured response curve, with its uncertainty, enters the model (repeat per camera)",
    )
    p.add_argument(
        "--channel",
        choices=("red", "green", "blue"),
        help="fit one colour channel of a Bayer dataset, predicted with the profile's QE of that channel "
        "(default: the whole mosaic, with its combined QE)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def run(args) -> int:
    from uwlab.experiments.calibration.pipeline import calibrate

    bar, update = tau_bar("sampling")
    with bar:
        calibration = calibrate(
            args.dataset,
            args.config,
            args.out,
            args.train,
            progress=update,
            model=args.model,
            sensors=args.sensor,
            channel=args.channel,
            held_out=args.held_out,
            dask=args.dask,
        )
    summary = calibration.summary
    if args.json:
        json.dump(summary, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    print(f"calibration written to {calibration.out}" + (f" ({args.channel} channel)" if args.channel else ""))
    coverage = summary["predictive_coverage"]
    print(
        f"{summary['model']} model: {'adequate' if summary['model_adequate'] else 'NOT adequate'}; "
        f"{100 * coverage['held_out_inside_95']:.0f} % of held-out points inside their 95 % bands "
        f"(median half-width ±{coverage['held_out_half_width_percent']:.2g} % for median errors of "
        f"{coverage['held_out_error_percent']:.2g} %)"
    )
    print(
        f"converged: {summary['converged']} ({summary['steps']} steps, {summary['tau_multiple']:.0f} τ, "
        f"acceptance {summary['acceptance_fraction']:.2f})"
    )
    print(f"{'parameter':<26}{'median':>12}{'68 % interval':>26}{'truth':>10}")
    for name, p in summary["parameters"].items():
        truth = p.get("truth")
        print(
            f"{name:<26}{p['median']:>12.4g}   [{p['p16']:.4g}, {p['p84']:.4g}]".ljust(64)
            + (f"{truth:>10.4g}" if truth is not None else f"{'':>10}")
        )
    for note in summary["warnings"]:
        print(f"warning: {note}")
    for pair in summary["not_separable"]:
        print(f"not separable by these data: {pair['a']} and {pair['b']} (correlation {pair['rho']:+.2f})")
    return 0
