"""Issue 36's audit campaigns in one run: the hostile requests against a served explorer
(`benchmarks/hostile_requests.py`) and the malformed light definitions on the instrument twins
(`benchmarks/malformed_definitions.py`), with the counts the issue's targets name.

Targets: 0 file contents returned or quoted outside the allowed folders, 0 answers 500, 0 off-site redirects, every
held connection closed within 30 s while normal requests answer within 1 s; 0 over-limit set points and 0 tracebacks
over every malformed definition.

Usage: python benchmarks/audit_campaigns.py   (prints JSON)
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import hostile_requests
import malformed_definitions


def main() -> dict:
    web = hostile_requests.main()
    lights = malformed_definitions.main()
    twins = lights["twins"].values()
    return {
        "benchmark": "audit_campaigns",
        "web": {
            key: web[key]
            for key in (
                "requests_tried",
                "answers_500",
                "file_contents_leaked",
                "offsite_redirects",
                "held_connections",
                "held_connections_closed",
                "worst_close_s",
                "worst_normal_latency_s",
            )
        },
        "lights": {
            "definitions_tried": sum(t.get("runs", 0) for t in twins),
            "over_limit_set_points": sum(t.get("over_limit_set_points", 0) for t in twins),
            "tracebacks": sum(t.get("tracebacks", 0) for t in twins),
        },
        "details": {"web": web, "lights": lights},
    }


if __name__ == "__main__":
    print(json.dumps(main(), indent=1))
