"""`uwlab sweep PLAN.toml`: run a sweep plan into a dataset (resumable), on the tank or the simulated rig."""

from __future__ import annotations

import json
import math
import sys

from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.dataset_check import summarize
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.sweep import Progress
from uwlab.experiments.dataset import Dataset


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
        "--non-interactive",
        action="store_true",
        help="never prompt the operator (manual aperture, focus and target-distance changes are refused)",
    )
    p.add_argument("--json", action="store_true", help="print the dataset summary as one JSON object")
    p.set_defaults(func=run)


def _confirm(message: str) -> None:
    reply = input(f"{message}, then press Enter (or type 'q' to stop): ")
    if reply.strip().lower() in ("q", "quit"):
        raise ConfigError("operator", reply.strip(), "stopped at the prompt")


def _ask_value(message: str, requested: float) -> float:
    """The value the operator set by hand: Enter accepts the one requested, a number gives another."""
    reply = input(f"{message}; press Enter when done, or type the value set (or 'q' to stop): ").strip()
    if reply.lower() in ("q", "quit"):
        raise ConfigError("operator", reply, "stopped at the prompt")
    if not reply:
        return requested
    try:
        value = float(reply)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and value > 0):
        raise ConfigError("operator", reply, "expected a positive number in metres (the value set) or Enter")
    return value


def run(args) -> int:
    from uwlab.experiments.acquisition.session import progress_text, run_session
    from uwlab.progress import bar

    plan = load_plan(args.plan)
    for notice in plan.notices:
        print(f"uwlab sweep: {notice}", file=sys.stderr)
    with bar(desc="sweep", unit="point") as shown:

        def progress(event: Progress) -> None:
            shown.total = event.total
            shown.set_position(event.done, progress_text(event))

        root = run_session(
            plan,
            args.resume or args.out,
            resume=bool(args.resume),
            sim=args.sim,
            force=args.force,
            confirm=None if args.non_interactive else _confirm,
            ask_value=None if args.non_interactive else _ask_value,
            progress=progress,
        )
    summary = summarize(Dataset.open(root))
    if args.json:
        print(json.dumps(summary))
    else:
        print(
            f"dataset {summary['path']}: {summary['points_done']}/{summary['points_total']} points, "
            f"{summary['saturated_points']} saturated"
        )
    return 0
