"""`uwlab sweep` and `uwlab dataset show` as subprocesses: crash and resume, Ctrl-C, refusals, exit codes."""

import json
import os
import signal

import pytest

from uwlab.experiments.dataset import Dataset
from uwlab.experiments.acquisition.plan import load_plan

from tests.support.cli_process import finish, points_recorded, run, uwlab, wait_until
from tests.support.plans import camera, write_plan

PLAN = {
    "name": "cli-unit",
    "camera": camera(32, 32),
    "defaults": {"kind": "exposure", "values": {"start": 50, "stop": 400, "num": 8}, "settle_s": 0.15, "dark": "none"},
    "sweeps": [{"id": "first"}, {"id": "second", "kind": "light-level", "values": [0.3, 0.6, 1.0], "exposure_us": 200}],
}


@pytest.fixture
def plan_path(tmp_path):
    return write_plan(tmp_path / "plan.toml", **PLAN)


def test_crash_then_interrupt_then_resume_completes_exactly_the_missing_points(tmp_path, plan_path):
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    out = tmp_path / "data"
    crashed = uwlab("sweep", plan_path, "--sim", "--out", out, env=env)
    try:
        wait_until(lambda: points_recorded(out) >= 3, crashed, "3 points are recorded")
    finally:
        os.killpg(crashed.pid, signal.SIGKILL)  # the sweep and its simulators: a crash
        crashed.communicate()
    after_crash = Dataset.open(out).completed()
    assert 3 <= len(after_crash) < 11 and Dataset.open(out).metadata["finished_utc"] is None

    interrupted = uwlab("sweep", plan_path, "--sim", "--resume", out, env=env)
    wait_until(lambda: points_recorded(out) > len(after_crash), interrupted, "one more point is recorded")
    interrupted.send_signal(signal.SIGINT)  # Ctrl-C
    code, _, err = finish(interrupted)
    assert code == 130 and "interrupted" in err
    assert Dataset.open(out).completed() >= after_crash

    code, stdout, err = run("sweep", plan_path, "--sim", "--resume", out, "--json", env=env)
    assert code == 0, err
    points = Dataset.open(out).points()
    expected = {(s.table.id, p.index) for s in load_plan(plan_path).sweeps for p in s.points()}
    keys = list(zip(points["sweep_id"], points["point_index"], strict=True))
    assert len(keys) == len(set(keys)) and set(keys) == expected  # as a non-interrupted run
    summary = json.loads(stdout)
    assert summary["points_done"] == summary["points_total"] == 11 and summary["finished_utc"]


def test_refusals_exit_2_with_one_line(tmp_path, plan_path):
    existing = tmp_path / "existing"
    with Dataset.create(
        existing, {"sweep": [{"id": "x", "kind": "dark", "values": [1]}]}, plan_sha256="0" * 64, sim=True
    ) as other:
        other.append_point({"sweep_id": "x", "point_index": 0, "kind": "dark", "frames": 2})
    code, _, err = run("sweep", plan_path, "--sim", "--out", existing)
    assert code == 2 and "--force" in err and len(err.strip().splitlines()) == 1
    code, _, err = run("sweep", plan_path, "--sim", "--resume", existing)
    assert code == 2 and "different plan" in err and len(err.strip().splitlines()) == 1
    bad = write_plan(tmp_path / "bad.toml", **{**PLAN, "defaults": {**PLAN["defaults"], "settle_s": -1}})
    code, _, err = run("sweep", bad, "--sim", "--out", tmp_path / "x")
    assert code == 2 and "defaults" not in err and "sweep.first.settle_s" in err


def test_dataset_show(tmp_path):
    plan = {"name": "p", "sweep": [{"id": "a", "kind": "exposure", "values": [1, 2, 3]}]}
    data = Dataset.create(tmp_path, plan, plan_sha256="f" * 64, sim=True)
    data.append_point(
        {
            "sweep_id": "a",
            "point_index": 0,
            "kind": "exposure",
            "frames": 2,
            "saturated": True,
            "t_start_ns": 1_700_000_000_000_000_000,
            "t_end_ns": 1_700_000_001_000_000_000,
        }
    )
    code, out, err = run("dataset", "show", tmp_path, "--json")
    summary = json.loads(out)
    assert code == 0 and summary["points_done"] == 1 and summary["points_total"] == 3
    assert summary["saturated_points"] == 1 and summary["plan_sha256"] == "f" * 64
    assert summary["time_span"]["start_utc"].startswith("2023-11-14")
    code, out, _ = run("dataset", "show", tmp_path)
    assert code == 0 and "1/3" in out
