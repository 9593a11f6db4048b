"""`uwlab demo`: the main job on the simulated rig — campaign, calibration, validation, report."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from uwlab.progress import bar, tau_bar


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "demo",
        description="Simulated rig → exposure sweeps (IMX250, ICX285 × three lens settings) → "
        "Bayesian calibration → validation report. Prints the report's path.",
    )
    p.add_argument("--out", metavar="DIR", help="new output directory (default: out/demo-<date>-<time>)")
    p.add_argument(
        "--world",
        choices=("ideal", "tank", "turbid"),
        help="what renders the simulated rig: ideal (the paper's model itself), tank (the tank renderer: "
        "real beam, refraction, backscatter, stray light, drift, sensor realism), turbid (the tank "
        "with added scatterers); default: the rig's, tank",
    )
    p.add_argument(
        "--model",
        choices=("paper", "extended"),
        help="the chain the calibration fits: the paper's, or the extended one (lights' placement and "
        "beam, the board, backscatter, vignetting); default: the rig's, extended",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of all the simulated noise: camera, spectrometer (default 0; equal seeds give equal numbers)",
    )
    p.add_argument(
        "--sensor",
        choices=("emva", "profile"),
        default="emva",
        help="fit with each camera as characterised first on the simulated EMVA bench (emva, default: its measured "
        "response curve) or with its hand-written sensor profile (profile: a linear response)",
    )
    p.add_argument("--json", action="store_true", help="print summary.json")
    p.set_defaults(func=run)


def run(args) -> int:
    from uwlab.experiments.demo import run_demo
    from uwlab.model.schema import Seed, check

    check(Seed, args.seed, "--seed")
    if args.out is None:
        Path("out").mkdir(exist_ok=True)
    out = Path(args.out) if args.out else Path("out") / time.strftime("demo-%Y%m%d-%H%M%S")
    sweep_bar = bar(desc="sweeps", unit="point")  # drawn at the first point: nothing for refused input
    fit_bar, fit_progress = tau_bar("calibration")

    def sweep_progress(event) -> None:
        sweep_bar.total = event.total
        sweep_bar.update(1)
        sweep_bar.set_postfix_str(event.sweep_id)

    with sweep_bar, fit_bar:
        summary = run_demo(
            out,
            sweep_progress,
            fit_progress,
            seed=args.seed,
            world=args.world,
            model=args.model,
            sensors=args.sensor,
        )
    if args.json:
        json.dump(summary, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    verdict = "adequate" if summary["model_adequate"] else "NOT adequate"
    print(f"{summary['model']} model in the {summary['world']} world: {verdict}")
    width = max(24, *(len(name) + 2 for name in summary["parameters"]))
    print(f"{'parameter':<{width}}{'truth':>10}{'median':>10}   95 % interval")
    for name, p in summary["parameters"].items():
        truth = "—" if p["truth"] is None else f"{p['truth']:.4g}"
        print(f"{name:<{width}}{truth:>10}{p['median']:>10.4g}   [{p['p2_5']:.4g}, {p['p97_5']:.4g}]")
    print(f"converged: {summary['converged']}")
    coverage = summary["predictive_coverage"]
    print(
        f"held-out points inside their 95 % bands: {100 * coverage['held_out_inside_95']:.0f} % "
        f"(median half-width ±{coverage['held_out_half_width_percent']:.2g} % for median errors of "
        f"{coverage['held_out_error_percent']:.2g} %)"
    )
    ninety = coverage.get("held_out_90")
    if ninety:
        print(
            f"held-out points inside their 90 % bands: {100 * ninety['inside']:.0f} % "
            f"(median half-width ±{ninety['half_width_percent']:.2g} %)"
        )
    for row in summary["cross_configuration"]:
        print(
            f"  {row['sweep_id']:<18} held out: median error {100 * row['median_abs_rel_error']:.2f} %, "
            f"{100 * row['inside_95']:.0f} % inside"
        )
    geometry = summary.get("geometry")
    if geometry:
        print(f"geometry: {'adequate' if geometry['adequate'] else 'NOT adequate'} ({geometry['headline']})")
    for note in summary["warnings"]:
        print(f"warning: {note}")
    print(summary["report"])
    return 0
