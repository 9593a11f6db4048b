"""`uwlab sweep PLAN.toml`: run a sweep plan into a dataset (resumable), on the tank or the simulated rig."""

from __future__ import annotations

import json
import sys

from tqdm import tqdm

from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.rigs import HardwareRig
from uwlab.experiments.acquisition.sim_rig import SimRig
from uwlab.experiments.acquisition.sweep import Progress, SweepRunner, open_for_resume
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.acquisition.dataset_check import summarize
from uwlab.outputs import output_dir


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "sweep",
        description="Measure every point of a sweep plan and append it to a dataset as it "
        "completes. Exit codes: 0 done, 2 bad input or device failure, "
        "130 interrupted (the dataset stays valid; complete it with --resume). "
        "A dataset has one writer at a time (its lock names the holder).",
    )
    p.add_argument("plan", metavar="PLAN.toml", help="sweep plan (see docs/sweeps.md)")
    p.add_argument("--sim", action="store_true", help="run on the simulated rig (camera, light, spectrometer)")
    target = p.add_mutually_exclusive_group()
    target.add_argument("--out", metavar="DIR", help="new dataset directory (default: <plan name>-dataset)")
    target.add_argument("--resume", metavar="DIR", help="complete the missing points of this dataset")
    p.add_argument(
        "--force",
        action="store_true",
        help="overwrite an existing dataset at --out (one with no recorded point is replaced without it)",
    )
    p.add_argument(
        "--non-interactive", action="store_true", help="never prompt the operator (manual aperture changes are refused)"
    )
    p.add_argument("--json", action="store_true", help="print the dataset summary as one JSON object")
    p.set_defaults(func=run)


def _confirm(message: str) -> None:
    reply = input(f"{message}, then press Enter (or type 'q' to stop): ")
    if reply.strip().lower() in ("q", "quit"):
        raise ConfigError("operator", reply.strip(), "stopped at the prompt")


def _dataset(args, plan) -> Dataset:
    """The dataset to write, its lock held: checked before any device is opened."""
    if args.resume:
        output_dir(args.resume, "--resume")
        return open_for_resume(args.resume, plan, args.sim, purpose="uwlab sweep --resume")
    out = output_dir(args.out or f"{plan.path.stem}-dataset", "--out")
    return Dataset.create(out, plan.raw, plan_sha256=plan.sha256, sim=args.sim, force=args.force, purpose="uwlab sweep")


def run(args) -> int:
    plan = load_plan(args.plan)
    with _dataset(args, plan) as dataset:
        rig = SimRig(plan.rig_path) if args.sim else HardwareRig(plan, None if args.non_interactive else _confirm)
        done = len(dataset.completed())
        with (
            rig,
            tqdm(
                total=plan.total_points(), initial=done, desc="sweep", unit="point", file=sys.stderr, disable=None
            ) as bar,
        ):

            def progress(event: Progress) -> None:
                latest = event.latest
                signal = "n/a" if latest["signal_dn"] is None else f"{latest['signal_dn']:.1f}"
                bar.set_postfix_str(
                    f"{event.sweep_id}#{event.point_index} t={latest['exposure_us']:g}us "
                    f"signal={signal}DN{' SAT' if latest['saturated'] else ''}"
                )
                bar.update(1)

            SweepRunner(plan, dataset, rig, progress).run()
    summary = summarize(Dataset.open(dataset.root))
    if args.json:
        print(json.dumps(summary))
    else:
        print(
            f"dataset {summary['path']}: {summary['points_done']}/{summary['points_total']} points, "
            f"{summary['saturated_points']} saturated"
        )
    return 0
