"""The public surface: every name of `uwlab.__all__` resolves, is documented with an example, and `import uwlab`
loads none of the heavy libraries (the names are imported on first use)."""

import inspect
import json
import subprocess
import sys

import pytest

import uwlab
from tests.support.paths import ROOT

HEAVY = (
    "numpy",
    "pandas",
    "scipy",
    "matplotlib",
    "arviz",
    "xarray",
    "emcee",
    "pyarrow",
    "uwlab.api",
    "uwlab.experiments",
    "uwlab.model",
)


def test_import_uwlab_loads_no_heavy_module():
    code = f"import json, sys, uwlab; print(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
        env={"PYTHONPATH": str(ROOT), "PATH": ""},
    )
    assert json.loads(out.stdout) == []


@pytest.mark.parametrize("name", [n for n in uwlab.__all__ if n != "__version__"])
def test_every_public_name_resolves_and_has_an_example(name):
    value = getattr(uwlab, name)
    doc = inspect.getdoc(value) or ""
    module_doc = inspect.getdoc(sys.modules[value.__module__]) or ""
    assert ">>>" in doc or (">>>" in module_doc and "module docstring" in doc) or "See `" in doc, name
    assert name in dir(uwlab)


def test_the_cli_verbs_have_their_python_names():
    """What a user learns in the CLI carries over: each workflow verb is a function of the same name."""
    for verb in ("evaluate", "grid", "solve", "sweep", "characterize", "fit", "report", "grab"):
        assert callable(getattr(uwlab, verb))


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'nonesuch'"):
        uwlab.nonesuch  # noqa: B018


def test_docs_api_has_every_name_and_every_readme_workflow():
    import re

    doc = (ROOT / "docs" / "api.md").read_text()
    for name in uwlab.__all__:
        if name != "__version__":
            assert f"{name}(" in doc or f"`{name}`" in doc or f"{name}." in doc, name
    readme = (ROOT / "README.md").read_text()
    rows = re.findall(r"^\| `(uwlab [a-z]+)", readme, flags=re.M)
    assert len(rows) >= 10
    python_rows = re.findall(r"^\| `(uwlab [a-z]+)", doc, flags=re.M)
    assert set(rows) <= set(python_rows)
