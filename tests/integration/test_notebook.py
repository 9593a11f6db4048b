"""examples/tank-campaign.ipynb runs top to bottom on the simulated rig in a Jupyter kernel (nbclient), shows the
API's figures inline, ends with an adequate model (as `uwlab demo` does), and is kept in git without outputs."""

import ast
import base64
import os
import sys

import nbformat
import pytest

from tests.support.paths import ROOT

NOTEBOOK = ROOT / "examples" / "tank-campaign.ipynb"


def test_the_notebook_is_stored_without_outputs():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code and all(c.outputs == [] and c.execution_count is None for c in code)


def test_the_notebook_runs_on_the_simulated_rig(tmp_path, monkeypatch):
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    # the kernel is this interpreter (jupyter_client replaces the spec's "python" by sys.executable) importing
    # this tree's uwlab
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    monkeypatch.setenv("PATH", os.pathsep.join([os.path.dirname(sys.executable), os.environ.get("PATH", "")]))
    nb = nbformat.read(NOTEBOOK, as_version=4)
    client = nbclient.NotebookClient(
        nb, kernel_name="python3", timeout=600, resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()
    outputs, images, printed = {}, {}, []
    for cell in nb.cells:
        for output in cell.get("outputs", []):
            assert output.output_type != "error", output
            if output.output_type == "stream" and output.name == "stdout":
                printed.append(output.text)
            if output.output_type == "execute_result":
                outputs[cell.source.splitlines()[-1]] = output.data["text/plain"]
                images[cell.source.splitlines()[-1].split("  #")[0]] = output.data.get("image/png")
    # the API's figures show inline as images, though the notebook never imports pyplot
    for shown in ('figures["dof"]', 'camera.figures()["snr"]', 'fit.figures()["response"]'):
        assert images[shown] and base64.b64decode(images[shown]).startswith(b"\x89PNG"), shown
    # it ends as `uwlab demo` does: the cameras characterised on the bench make the extended model adequate
    assert "extended model: adequate\n" in "".join(printed)
    answer = ast.literal_eval(outputs[' "probability": float(calibrated["probability"].iloc[0])}'])
    assert answer["probability"] >= 0.9
    # the simulated light gives 80 % of its rated flux: the calibrated design needs more light than the nominal
    assert answer["calibrated_lm"] > answer["nominal_lm"]
