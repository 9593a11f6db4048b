"""Datasets through the real `uwlab` command (subprocesses, real signals): one writer at a time, Ctrl-C and SIGKILL,
stale rig folders, read-only output, a sweep whose devices never opened, `dataset check` and `--resume`."""

import json
import os
import resource
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.dataset import Dataset, spectra_frame
from uwlab.experiments.acquisition.dataset_check import check
from uwlab.lockfile import read_holder

from tests.support.cli_process import finish, points_recorded, run, uwlab, wait_until
from tests.support.plans import camera, write_plan


def plan_file(tmp_path: Path, points: int, settle_s: float = 0.0, name: str = "plan", **tables) -> Path:
    sweep = {
        "id": "a",
        "kind": "exposure",
        "values": {"start": 50, "stop": 400, "num": points},
        "settle_s": settle_s,
        "dark": "none",
    }
    return write_plan(tmp_path / f"{name}.toml", name, [sweep], camera=camera(16, 16), **tables)


def one_line(err: str) -> bool:
    return len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_a_second_writer_is_refused_naming_the_holder_and_no_point_is_lost(tmp_path):
    plan, out = plan_file(tmp_path, points=16, settle_s=0.5), tmp_path / "data"
    first = uwlab("sweep", plan, "--sim", "--out", out)
    wait_until(lambda: points_recorded(out) >= 1, first, "a first point")
    others = [
        uwlab("sweep", plan, "--sim", "--resume", out),
        uwlab("sweep", plan, "--sim", "--out", out, "--force"),
        uwlab("dataset", "check", out, "--repair"),
    ]
    for other in others:
        code, _, err = finish(other)
        assert code == 2 and one_line(err) and f"pid {first.pid} on host {socket.gethostname()}" in err, err
    assert first.poll() is None  # the refusals happened while the first sweep was writing
    code, _, err = finish(first)
    assert code == 0, err
    data = Dataset.open(out)
    assert sorted(data.points()["point_index"]) == list(range(16)) and check(data).ok
    assert read_holder(out / "lock") is None  # released


def test_ctrl_c_at_start_up_and_while_measuring_exits_130_in_one_line_and_the_dataset_resumes(tmp_path):
    plan, out = plan_file(tmp_path, points=4, settle_s=0.3), tmp_path / "data"
    for delay in (0.0, 0.4):  # as the dataset appears, then while the simulators start
        started = uwlab("sweep", plan, "--sim", "--out", out)
        wait_until(
            lambda pid=started.pid: getattr(read_holder(out / "lock"), "pid", None) == pid, started, "the dataset"
        )
        time.sleep(delay)
        os.killpg(started.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group
        code, _, err = finish(started)
        assert code == 130 and err == "uwlab sweep: interrupted\n", err
    measuring = uwlab("sweep", plan, "--sim", "--out", out)  # nothing recorded yet: no --force needed
    wait_until(lambda: points_recorded(out) >= 1, measuring, "a first point")
    os.killpg(measuring.pid, signal.SIGINT)
    code, _, err = finish(measuring)
    assert code == 130 and err == "uwlab sweep: interrupted\n", err
    kept = Dataset.open(out).completed()
    code, stdout, err = run("sweep", plan, "--sim", "--resume", out, "--json")
    assert code == 0, err
    assert json.loads(stdout)["state"] == "complete" and Dataset.open(out).completed() >= kept


def test_after_sigkill_the_lock_is_taken_over_and_only_stale_rig_folders_are_removed(tmp_path):
    temp = tmp_path / "tmp"
    temp.mkdir()
    env = {**os.environ, "TMPDIR": str(temp)}
    plan, out = plan_file(tmp_path, points=6, settle_s=0.3), tmp_path / "data"
    killed = uwlab("sweep", plan, "--sim", "--out", out, env=env)
    wait_until(lambda: points_recorded(out) >= 1, killed, "a first point")
    os.killpg(killed.pid, signal.SIGKILL)
    killed.communicate()
    left = list(temp.glob("uwlab-simrig-*"))
    assert len(left) == 1 and read_holder(out / "lock").pid == killed.pid
    live_folder, young, old = temp / "uwlab-simrig-live", temp / "uwlab-simrig-young", temp / "uwlab-simrig-old"
    for folder in (live_folder, young, old):
        folder.mkdir()
    os.utime(old, (time.time() - 3600, time.time() - 3600))
    live = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from uwlab.lockfile import OwnerLock; "
            f"lock = OwnerLock({str(live_folder / 'owner.lock')!r}, 'live rig'); lock.acquire(); "
            "print('held', flush=True); time.sleep(600)",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert live.stdout.readline() == "held\n"
        code, _, err = run("sweep", plan, "--sim", "--resume", out, env=env)
        assert code == 0, err
        assert sorted(p.name for p in temp.iterdir()) == ["uwlab-simrig-live", "uwlab-simrig-young"]
    finally:
        live.kill()
        live.wait()
    assert sorted(Dataset.open(out).points()["point_index"]) == list(range(6))


def _no_writes():
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))


def test_resume_into_read_only_output_is_one_line_and_changes_nothing(tmp_path):
    plan_path = plan_file(tmp_path, points=2)
    plan, out = load_plan(plan_path), tmp_path / "data"
    Dataset.create(out, plan.raw, plan_sha256=plan.sha256, sim=True).close()
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    out.chmod(0o555)  # read-only for a user; root writes anyway, so no file may grow either (RLIMIT_FSIZE = 0)
    try:
        process = uwlab(
            "sweep",
            plan_path,
            "--sim",
            "--resume",
            out,
            preexec_fn=_no_writes,
            env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"},
        )
        code, _, err = finish(process)
    finally:
        out.chmod(0o755)
    assert code == 2 and one_line(err) and "nothing was changed" in err, err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_a_sweep_whose_devices_never_opened_leaves_an_empty_dataset_the_same_command_reuses(tmp_path):
    hardware = plan_file(
        tmp_path, points=2, name="hardware", lights=[{"instrument": "uwlab-ascii", "resource": "/nonexistent/tty9"}]
    )
    out = tmp_path / "data"
    for _ in range(2):  # the same command fails the same way: on the device, not on the dataset it left
        code, _, err = run("sweep", hardware, "--out", out)
        assert code == 2 and one_line(err) and "/nonexistent/tty9" in err and "--force" not in err, err
    code, stdout, _ = run("dataset", "show", out)
    assert code == 0 and ": empty" in stdout and "finished: no" in stdout and "points 0/2" in stdout
    code, _, err = run("sweep", plan_file(tmp_path, points=2), "--sim", "--out", out)
    assert code == 0, err
    assert len(Dataset.open(out).completed()) == 2


def test_dataset_check_finds_damage_resume_refuses_repair_sets_it_aside_and_resume_completes(tmp_path):
    plan_path = plan_file(tmp_path, points=4)
    plan, out = load_plan(plan_path), tmp_path / "data"
    with Dataset.create(out, plan.raw, plan_sha256=plan.sha256, sim=True) as data:
        for index in range(3):
            nm = np.arange(380.0, 781.0)
            data.append_point(
                {"sweep_id": "a", "point_index": index, "kind": "exposure", "frames": 2},
                spectra_frame("a", index, [("target", nm, np.full_like(nm, 1e-3))]),
            )
    damaged = out / Dataset.open(out).store.parts[1].tables["spectra"].file
    content = bytearray(damaged.read_bytes())
    content[len(content) // 2] ^= 0x10
    damaged.write_bytes(bytes(content))
    code, stdout, _ = run("dataset", "check", out)
    assert code == 1 and damaged.name in stdout and "SHA-256" in stdout
    code, _, err = run("sweep", plan_path, "--sim", "--resume", out)
    assert code == 2 and one_line(err) and "--repair" in err, err
    code, stdout, err = run("dataset", "check", out, "--repair", "--json")
    report = json.loads(stdout)
    assert code == 0 and report["ok"] and report["points"] == {"a": {"done": 2, "total": 4}}, err
    assert list((out / "quarantine").rglob(damaged.name))
    code, stdout, err = run("sweep", plan_path, "--sim", "--resume", out, "--json")
    assert code == 0 and json.loads(stdout)["state"] == "complete", err
    code, stdout, _ = run("dataset", "check", "--json", tmp_path / "not-there")
    assert code == 2


@pytest.mark.parametrize("args", [("dataset", "show"), ("dataset", "check"), ("sweep", "PLAN", "--sim", "--resume")])
def test_a_folder_that_is_not_a_dataset_is_one_line_exit_2(tmp_path, args):
    plan = plan_file(tmp_path, points=2)
    code, _, err = run(*[plan if a == "PLAN" else a for a in args], tmp_path)
    assert code == 2 and one_line(err) and "not a dataset" in err and not (tmp_path / "lock").exists()
