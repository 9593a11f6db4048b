"""uwlab.provenance: the record names what each source of truth says (the packages' own versions, git, the BLAS's
thread setting), and the report's provenance rows read every form a dataset has held."""

import shutil
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
import scipy

import uwlab
from uwlab.experiments.report import _dataset_made_with
from uwlab.provenance import PACKAGES, UNKNOWN, _commit, provenance, provenance_line

ROOT = Path(uwlab.__file__).resolve().parent.parent


def test_the_record_names_the_versions_python_and_the_cpu():
    record = provenance()
    assert record["uwlab"] == uwlab.__version__
    assert record["packages"]["numpy"] == np.__version__ and record["packages"]["scipy"] == scipy.__version__
    installed = {}
    for name in PACKAGES:
        try:
            installed[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    assert record["packages"] == installed  # as importlib.metadata reads them (opencv's, colour-science's names)
    assert record["python"].startswith(".".join(map(str, sys.version_info[:3])))
    if Path("/proc/cpuinfo").exists():
        assert record["cpu"] != UNKNOWN and record["cpu"] in Path("/proc/cpuinfo").read_text()
    line = provenance_line(record)
    assert f"numpy {np.__version__}" in line and f"CPU {record['cpu']}" in line


@pytest.mark.skipif(not (ROOT / ".git").exists() or shutil.which("git") is None, reason="not a git checkout")
def test_the_commit_is_the_checkouts_head():
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True, check=True)
    assert provenance()["commit"] == head.stdout.strip()


@pytest.mark.skipif(shutil.which("git") is None, reason="no git")
def test_a_checkout_is_modified_by_a_change_to_a_tracked_file_only(tmp_path):
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(tmp_path), *args], capture_output=True, text=True, check=True).stdout

    git("init", "-q")
    assert _commit.__wrapped__(tmp_path) == (UNKNOWN, None)  # no commit yet
    (tmp_path / "tracked.txt").write_text("a\n")
    git("add", "tracked.txt")
    git("-c", "user.name=t", "-c", "user.email=t@example.org", "commit", "-qm", "first")
    head = git("rev-parse", "HEAD").strip()
    (tmp_path / "untracked.txt").write_text("b\n")
    assert _commit.__wrapped__(tmp_path) == (head, False)
    (tmp_path / "tracked.txt").write_text("c\n")
    assert _commit.__wrapped__(tmp_path) == (head, True)


def test_the_blas_thread_count_follows_its_setting():
    threadpoolctl = pytest.importorskip("threadpoolctl")
    with threadpoolctl.threadpool_limits(limits=1, user_api="blas"):
        assert provenance()["blas"]["threads"] == 1
    assert provenance()["blas"]["threads"] == threadpoolctl.threadpool_info()[0]["num_threads"]


def test_without_threadpoolctl_the_blas_numpy_was_built_with_and_the_environments_thread_count(monkeypatch):
    monkeypatch.setitem(sys.modules, "threadpoolctl", None)  # import fails
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")
    blas = provenance()["blas"]
    assert (
        blas["threads"] == 3 and blas["library"] == np.show_config(mode="dicts")["Build Dependencies"]["blas"]["name"]
    )
    monkeypatch.delenv("OPENBLAS_NUM_THREADS")
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert provenance()["blas"]["threads"] is None
    assert "an unknown number of threads" in provenance_line(provenance())


def test_the_reports_rows_for_a_dataset_started_resumed_or_older():
    started, resumed = provenance(), {**provenance(), "cpu": "Other CPU"}
    metadata = {
        "provenance": started,
        "resumed": [{"utc": "2026-01-02T03:04:05+00:00", "host": "b", "provenance": resumed}],
    }
    rows = _dataset_made_with(Path("d"), metadata)
    assert rows == [
        ("dataset d", provenance_line(started)),
        ("dataset d, resumed 2026-01-02T03:04:05+00:00 on b", provenance_line(resumed)),
    ]
    # written before provenance: its package versions; before those: said so
    assert _dataset_made_with(Path("d"), {"software": {"python": "3.11.7", "numpy": "1.26.4"}}) == [
        ("dataset d", "python 3.11.7, numpy 1.26.4")
    ]
    assert "not recorded" in _dataset_made_with(Path("d"), {})[0][1]
