"""The Python API as a newcomer runs it: a script saved outside the repository, without an
``if __name__ == "__main__":`` guard, run with the venv's python from another folder. The simulated rig's simulators
are processes of their own and never import (so never re-run) the script; the run ends with nothing left behind:
no held dataset lock, no simulator process, no simulated-rig folder. The script of docs/api.md ("The tank campaign
as a script") ends with an adequate model, as `uwlab demo` does."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import uuid
from pathlib import Path

from uwlab.lockfile import read_holder

from tests.support.paths import ROOT
from tests.support.plans import write_campaign

GUARDLESS = """\
import sys
import uwlab

print("script started", flush=True)
data = uwlab.sweep(sys.argv[1], "small", sim=True, progress=False)
print("points", len(data.points), flush=True)
"""


def run_script(script: Path, cwd: Path, tmp: Path, *args: str) -> tuple[subprocess.CompletedProcess, str]:
    """Run `script` with this interpreter from `cwd` (this tree's uwlab first on the path, temporary files in
    `tmp`); returns the finished process and the marker its environment (and so its children's) carried."""
    marker = f"uwlab-test-{uuid.uuid4()}"
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
        "TMPDIR": str(tmp),
        "UWLAB_SCRIPT_MARKER": marker,
    }
    done = subprocess.run(
        [sys.executable, str(script), *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=1200
    )
    return done, marker


def processes_carrying(marker: str) -> list[int]:
    """The live processes whose environment holds `marker` (the script's children outliving it)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if marker.encode() in (entry / "environ").read_bytes():
                    found.append(int(entry.name))
            except OSError:
                continue
    return found


def assert_nothing_left(dataset: Path, tmp: Path, marker: str) -> None:
    assert (dataset / "metadata.json").is_file()
    assert read_holder(dataset / "lock") is None, "the dataset's lock is still held or names a holder"
    assert processes_carrying(marker) == []
    assert list(tmp.glob("uwlab-simrig-*")) == []


def folders(tmp_path: Path) -> tuple[Path, Path, Path]:
    scripts, run, tmp = (tmp_path / name for name in ("scripts", "run", "tmp"))
    for folder in (scripts, run, tmp):
        folder.mkdir()
    return scripts, run, tmp


def test_a_script_without_a_main_guard_runs_once_and_leaves_nothing_behind(tmp_path):
    scripts, run, tmp = folders(tmp_path)
    plan = write_campaign(scripts / "plan.toml", "script-small", sweeps=1, values={"start": 50, "stop": 800, "num": 3})
    script = scripts / "campaign.py"
    script.write_text(GUARDLESS)
    done, marker = run_script(script, run, tmp, str(plan))
    assert done.returncode == 0, done.stderr
    assert done.stdout == "script started\npoints 3\n"
    assert "Traceback" not in done.stderr and "failed to start" not in done.stderr
    assert_nothing_left(run / "small", tmp, marker)


def docs_script() -> str:
    """The script of docs/api.md's "The tank campaign as a script"."""
    text = (ROOT / "docs" / "api.md").read_text()
    section = text.split("## The tank campaign as a script", 1)[1]
    return re.search(r"```python\n(.*?)```", section, flags=re.S).group(1)


def test_the_documented_script_ends_with_an_adequate_model(tmp_path):
    scripts, run, tmp = folders(tmp_path)
    script = scripts / "tank_campaign.py"
    script.write_text(docs_script())
    done, marker = run_script(script, run, tmp)
    assert done.returncode == 0, done.stderr
    assert "extended model: adequate\n" in done.stdout, done.stdout[-2000:]
    assert done.stdout.rstrip().endswith(str(Path("tank") / "report.html"))
    assert (run / "tank" / "report.html").is_file()
    assert sorted(p.name for p in run.glob("emva-*")) == ["emva-icx285alm", "emva-imx250m"]
    assert_nothing_left(run / "tank", tmp, marker)
