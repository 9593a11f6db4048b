"""uwlab.provenance in a fresh process: the SIMD extensions it names are those numpy was left to use (an AVX-512
machine's numbers differ from an AVX2 machine's; NPY_DISABLE_CPU_FEATURES makes one the other)."""

import json
import os
import subprocess
import sys

from tests.support.paths import ROOT

PRINT = "import json; from uwlab.provenance import provenance; print(json.dumps(provenance()['numpy_simd']))"


def simd(**environment: str) -> list[str] | None:
    done = subprocess.run(
        [sys.executable, "-c", PRINT],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT), **environment},
    )
    return json.loads(done.stdout)


def test_the_simd_named_is_what_numpy_was_left_to_use():
    everything = simd()
    assert everything is not None
    if not everything:
        return  # a CPU (or a numpy) with nothing to dispatch to beyond its baseline
    # disable the best target numpy dispatches to here: it is no longer named, the others still are
    best = everything[-1]
    assert simd(NPY_DISABLE_CPU_FEATURES=best) == everything[:-1]
