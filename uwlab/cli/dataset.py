"""`uwlab dataset show DIR`: summarise a sweep dataset; `uwlab dataset check DIR [--repair]`: verify (and repair) it."""

from __future__ import annotations

import json
from collections import Counter

from uwlab.experiments.dataset import Dataset
from uwlab.experiments.acquisition.dataset_check import check, repair, summarize

LISTED_PROBLEMS = 20


def register(subparsers) -> None:
    p = subparsers.add_parser("dataset", description="Inspect datasets written by `uwlab sweep`.")
    sub = p.add_subparsers(dest="dataset_command", required=True, metavar="{show,check}")
    s = sub.add_parser(
        "show",
        help="summarise a dataset",
        description="State (complete, incomplete, empty, damaged), sweeps, points done/total, "
        "saturated points, time span, devices, plan hash, problems found.",
    )
    s.add_argument("directory", metavar="DIR", help="dataset directory")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=run_show)
    c = sub.add_parser(
        "check",
        help="verify a dataset (and repair it)",
        description="Verify every part file (SHA-256, Parquet page checksums, rows, schema), every "
        "point (the row rule, NaN, duplicates, against the plan), spectra and raw frames. "
        "Exit codes: 0 passes, 1 problems found (listed), 2 not a dataset or bad input. "
        "--repair sets what fails aside in quarantine/ (nothing is deleted) so that "
        "`uwlab sweep --resume` measures those points again.",
    )
    c.add_argument("directory", metavar="DIR", help="dataset directory")
    c.add_argument(
        "--repair", action="store_true", help="set damaged parts and failing points aside (takes the dataset's lock)"
    )
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_check)


def run_show(args) -> int:
    summary = summarize(Dataset.open(args.directory))
    if args.json:
        print(json.dumps(summary))
        return 0
    span = summary["time_span"] or {}
    print(f"dataset {summary['path']} ({'simulated rig' if summary['sim'] else 'hardware'}): {summary['state']}")
    print(f"plan {summary['plan_name'] or '-'}  sha256 {summary['plan_sha256']}")
    print(
        f"points {summary['points_done']}/{summary['points_total']}, saturated {summary['saturated_points']}, "
        f"spectra rows {summary['spectra_rows']}"
    )
    finished = summary["finished_utc"] if summary["state"] == "complete" else "no"
    print(f"time {span.get('start_utc', '-')} .. {span.get('end_utc', '-')}  (finished: {finished or 'no'})")
    for sweep in summary["sweeps"]:
        camera = summary["devices"].get(sweep["id"], {}).get("camera") or {}
        print(
            f"  {sweep['id']:<24} {sweep['kind'] or '-':<12} {sweep['points_done']:>4}/{sweep['points_total']:<4} "
            f"saturated {sweep['saturated_points']:<4} {camera.get('model', '-')} {sweep['lens_label'] or ''}"
        )
    _print_problems(summary["problems"], args.directory)
    return 0


def run_check(args) -> int:
    if args.repair:
        with Dataset.open_for_writing(args.directory, purpose="uwlab dataset check --repair") as dataset:
            actions = repair(dataset)
    else:
        actions = []
    report = check(Dataset.open(args.directory))
    done = Counter(report.points["sweep_id"])
    points = {
        sweep_id: {"done": int(done.get(sweep_id, 0)), "total": total}
        for sweep_id, total in (report.totals or {}).items()
    }
    if args.json:
        print(
            json.dumps(
                {
                    "path": str(report.root),
                    "ok": report.ok,
                    "problems": [str(p) for p in report.problems],
                    "repairs": actions,
                    "points": points,
                    "stray_files": [str(p) for p in report.strays],
                }
            )
        )
        return 0 if report.ok else 1
    for action in actions:
        print(f"repair: {action}")
    counts = ", ".join(f"{sweep_id} {p['done']}/{p['total']}" for sweep_id, p in points.items())
    print(f"dataset {report.root}: {'ok' if report.ok else f'{len(report.problems)} problems'}; points {counts}")
    if report.strays:
        print(f"{len(report.strays)} files of interrupted writes, removed by the next writer")
    _print_problems([str(p) for p in report.problems], args.directory)
    return 0 if report.ok else 1


def _print_problems(problems: list[str], directory: str) -> None:
    for problem in problems[:LISTED_PROBLEMS]:
        print(f"  problem: {problem}")
    if len(problems) > LISTED_PROBLEMS:
        print(f"  ... and {len(problems) - LISTED_PROBLEMS} more (--json lists them all)")
    if problems:
        print(
            f"repair: `uwlab dataset check {directory} --repair` sets them aside; `uwlab sweep PLAN --resume "
            f"{directory}` measures those points again"
        )
