"""`uwlab dataset show DIR`: summarise a sweep dataset."""
from __future__ import annotations

import json

from uwlab.experiments.dataset import Dataset, summarize


def register(subparsers) -> None:
    p = subparsers.add_parser("dataset", help="inspect sweep datasets",
                              description="Inspect datasets written by `uwlab sweep`.")
    sub = p.add_subparsers(dest="dataset_command", required=True, metavar="show")
    s = sub.add_parser("show", help="summarise a dataset",
                       description="Sweeps, points done/total, saturated points, time span, devices, plan hash.")
    s.add_argument("directory", metavar="DIR", help="dataset directory")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=run_show)


def run_show(args) -> int:
    summary = summarize(Dataset.open(args.directory))
    if args.json:
        print(json.dumps(summary))
        return 0
    span = summary["time_span"] or {}
    print(f"dataset {summary['path']} ({'simulated rig' if summary['sim'] else 'hardware'})")
    print(f"plan {summary['plan_name']}  sha256 {summary['plan_sha256']}")
    print(f"points {summary['points_done']}/{summary['points_total']}, saturated {summary['saturated_points']}, "
          f"spectra rows {summary['spectra_rows']}")
    print(f"time {span.get('start_utc', '-')} .. {span.get('end_utc', '-')}  "
          f"(finished: {summary['finished_utc'] or 'no'})")
    for sweep in summary["sweeps"]:
        camera = summary["devices"].get(sweep["id"], {}).get("camera", {})
        print(f"  {sweep['id']:<24} {sweep['kind'] or '-':<12} {sweep['points_done']:>4}/{sweep['points_total']:<4} "
              f"saturated {sweep['saturated_points']:<4} {camera.get('model', '-')} {sweep['lens_label'] or ''}")
    return 0
