"""`uwlab report`: the self-contained HTML validation report of a campaign directory."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from uwlab.outputs import REPORT_FILE


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "report",
        description="Collect the datasets, calibrations and EMVA characterisations under DIR "
        "into one self-contained HTML file.",
    )
    p.add_argument("dir", help="campaign directory (datasets, `uwlab fit` and `uwlab emva` outputs)")
    p.add_argument("--out", metavar="FILE", help="report file, in an existing directory (default: DIR/report.html)")
    p.add_argument("--force", action="store_true", help="replace an existing report file")
    p.add_argument("--json", action="store_true", help='print {"report": PATH}')
    p.set_defaults(func=run)


def run(args) -> int:
    from uwlab.experiments.report import write_report

    out = args.out if args.out else Path(args.dir) / REPORT_FILE
    path = write_report(args.dir, out, replace=args.force)
    if args.json:
        json.dump({"report": str(path)}, sys.stdout)
        sys.stdout.write("\n")
    else:
        print(path)
    return 0
