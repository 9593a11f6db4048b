"""No uwlab module touches matplotlib's global state at import: `matplotlib.use` is never called and the backend a
notebook chose stays chosen (figures are made with the object API, `matplotlib.figure.Figure`)."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = r"""
import importlib, pkgutil
import matplotlib
matplotlib.use("svg")  # the user's choice, as a notebook's inline backend would be
calls = []
matplotlib.use = lambda *args, **kwargs: calls.append(args)
import uwlab
names = sorted(m.name for m in pkgutil.walk_packages(uwlab.__path__, "uwlab."))
for name in names:
    importlib.import_module(name)
print(len(names), matplotlib.get_backend(), len(calls))
"""


def test_importing_every_module_leaves_matplotlib_alone():
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, check=True).stdout.split()
    modules, backend, calls = int(out[0]), out[1], int(out[2])
    assert modules > 100  # every module was imported
    assert calls == 0, "a module called matplotlib.use at import"
    assert backend == "svg"
