"""Design grids in chunks: row order and values against one broadcast evaluation, streaming to Parquet/CSV with
bounded memory, refusals before evaluation, and the same bits on a Dask cluster (LocalCluster, and a `dask
scheduler` + `dask worker` pair as subprocesses on 127.0.0.1)."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.support.cli import one_line_error
from tests.support.cli_process import run
from tests.support.paths import EXAMPLE, ROOT
from uwlab.cli.main import main
from uwlab.errors import UwlabError
from uwlab.experiments import cluster
from uwlab.experiments.design import distributed, grid as grid_module
from uwlab.experiments.design.grid import DesignGrid, evaluate_grid, flatten_outputs, write_grid, write_part
from uwlab.model.build import build_design
from uwlab.model.evaluation import evaluate

AXES = {
    "operation.altitude_m": [0.5, 1.0, 2.0, 4.0, 7.0],
    "water.type": ["jerlov-I", "jerlov-5C"],
    "lens.f_number": [2.0, 2.8, 4.0, 5.6],
    "light.beam_half_angle_deg": [10.0, 25.0, 40.0],
}


def parts_bytes(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


@pytest.mark.parametrize("chunk_points", [1, 5, 7, 12, 60, 10_000])
def test_chunks_cover_the_grid_in_c_order_with_the_broadcast_values(example_raw, chunk_points):
    grid = DesignGrid(example_raw, AXES, chunk_points=chunk_points)
    frames = [grid.chunk(i) for i in range(grid.chunks)]
    assert all(0 < len(f) <= chunk_points for f in frames)
    frame = pd.concat(frames, ignore_index=True)
    assert len(frame) == grid.points == 5 * 2 * 4 * 3
    numeric = {k: np.asarray(v) for k, v in AXES.items() if k != "water.type"}
    for w, water in enumerate(AXES["water.type"]):
        rows = frame.iloc[w * 60 : (w + 1) * 60]
        assert (rows["water.type"] == water).all()
        raw = {s: dict(v) for s, v in example_raw.items()}
        raw["water"]["type"] = water
        mesh = {k: v.reshape([-1 if i == j else 1 for j in range(3)]) for i, (k, v) in enumerate(numeric.items())}
        whole = flatten_outputs(evaluate(build_design(raw).with_values(**mesh)))
        for key, values in mesh.items():
            assert rows[key].to_numpy().tolist() == np.broadcast_to(values, (5, 4, 3)).ravel().tolist()
        for key in ("mean_electrons", "snr_db", "dof_m_near", "image_average_mean_dn"):
            assert rows[key].to_numpy() == pytest.approx(np.broadcast_to(whole[key], (5, 4, 3)).ravel(), rel=1e-8)


def test_parquet_and_csv_stream_the_same_rows_as_in_memory(example_raw, tmp_path):
    grid = DesignGrid(example_raw, AXES, chunk_points=7)
    memory = pd.concat([grid.chunk(i) for i in range(grid.chunks)], ignore_index=True)
    summary = write_grid(grid, tmp_path / "g.parquet")
    parts = list((tmp_path / "g.parquet").iterdir())
    assert summary["points"] == 120 and summary["chunks"] == grid.chunks == len(parts)
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "g.parquet"), memory, check_exact=True)
    write_grid(grid, tmp_path / "g.csv")
    csv = pd.read_csv(tmp_path / "g.csv")
    pd.testing.assert_frame_equal(csv, memory, check_exact=True, check_dtype=False)
    with pytest.raises(UwlabError, match="exists"):
        write_grid(grid, tmp_path / "g.parquet")


def test_an_interrupted_write_leaves_nothing(example_raw, tmp_path, monkeypatch):
    grid = DesignGrid(example_raw, AXES, chunk_points=7)
    calls = []

    def failing(g, index, directory):
        calls.append(index)
        if index == 3:
            raise KeyboardInterrupt
        return write_part(g, index, directory)

    monkeypatch.setattr(grid_module, "write_part", failing)
    with pytest.raises(KeyboardInterrupt):
        write_grid(grid, tmp_path / "g.parquet")
    assert calls == [0, 1, 2, 3] and list(tmp_path.iterdir()) == []


def test_output_columns_can_be_chosen_and_unknown_ones_are_named(example_raw):
    grid = DesignGrid(example_raw, {"lens.f_number": [2.0, 4.0]}, outputs=("snr_db", "mean_fraction"))
    assert grid.schema.names == ["lens.f_number", "snr_db", "mean_fraction"]
    with pytest.raises(UwlabError, match="nope"):
        DesignGrid(example_raw, {"lens.f_number": [2.0]}, outputs=("nope",)).check()


def test_a_grid_too_large_for_memory_is_refused_before_evaluation(capsys, monkeypatch):
    monkeypatch.setattr(grid_module, "available_memory_bytes", lambda: 10 * 2**20)
    monkeypatch.setattr(DesignGrid, "chunk_columns", lambda self, i: pytest.fail("evaluated"))
    code = main(
        ["design", str(EXAMPLE), "--grid", "operation.altitude_m=0.1:100:0.01", "--grid", "lens.f_number=1:22:0.1"]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--out" in err and "GiB" in err


def test_grid_json_prints_the_rows_up_to_a_limit(capsys, example_raw):
    code = main(["design", str(EXAMPLE), "--grid", "operation.altitude_m=1,2", "--grid", "lens.f_number=2,4", "--json"])
    out = json.loads(capsys.readouterr().out)
    frame = evaluate_grid(example_raw, {"operation.altitude_m": [1, 2], "lens.f_number": [2, 4]})
    assert code == 0 and out["points"] == 4 and out["columns"] == list(frame.columns)
    assert [r["snr_db"] for r in out["rows"]] == frame["snr_db"].tolist()
    assert out["rows"][0]["saturated"] is False and out["rows"][0]["lens.f_number"] == 2.0
    code = main(
        ["design", str(EXAMPLE), "--grid", "operation.altitude_m=0.1:100:0.01", "--grid", "lens.f_number=2,4", "--json"]
    )
    captured = capsys.readouterr()
    assert code == 2 and captured.out == "" and "--out" in captured.err and captured.err.count("\n") == 1


def test_out_without_grid_writes_the_single_design_row(capsys, tmp_path):
    code = main(["design", str(EXAMPLE), "--json", "--out", str(tmp_path / "one.parquet")])
    result = json.loads(capsys.readouterr().out)
    row = pd.read_parquet(tmp_path / "one.parquet")
    assert code == 0 and len(row) == 1
    assert row["snr_db"].iloc[0] == result["snr_db"] and row["fov_deg_x"].iloc[0] == result["fov_deg"]["x"]


@pytest.mark.parametrize(
    "args, key",
    [
        (["design", "DIR"], "is a directory"),
        (["design", str(EXAMPLE), "--plot", "FILE/sub"], "--plot"),
        (["design", str(EXAMPLE), "--grid", "lens.f_number=2,4", "--dask", "local"], "--out"),
        (["design", str(EXAMPLE), "--dask", "local", "--out", "OUT/x.parquet"], "--dask"),
        (
            ["design", str(EXAMPLE), "--grid", "lens.f_number=2,4", "--dask", "udp://x", "--out", "OUT/x.parquet"],
            "--dask",
        ),
        (["design", str(EXAMPLE), "--grid", "lens.f_number=2,4", "--dask", "local", "--out", "OUT/x.csv"], "Parquet"),
        (["design", str(EXAMPLE), "--grid", "lens.f_number=2,4", "--out", "OUT/x.txt"], "--out"),
    ],
)
def test_bad_design_outputs_are_one_line(capsys, tmp_path, args, key):
    (tmp_path / "FILE").write_text("a file")
    args = [
        a.replace("DIR", str(tmp_path)).replace("FILE", str(tmp_path / "FILE")).replace("OUT", str(tmp_path))
        for a in args
    ]
    assert key in one_line_error(capsys, args)


def test_local_dask_cluster_writes_the_same_bits(example_raw, tmp_path):
    grid = DesignGrid(example_raw, AXES, chunk_points=11)
    write_grid(grid, tmp_path / "here.parquet")
    summary = distributed.write_grid_dask(grid, tmp_path / "dask.parquet", "local")
    assert summary["points"] == 120 and summary["workers"] >= 1
    assert parts_bytes(tmp_path / "dask.parquet") == parts_bytes(tmp_path / "here.parquet")


def _spawn(args, log):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen(
        [sys.executable, "-m", "dask", *args],
        stdout=log,
        stderr=subprocess.STDOUT,
        env=env,
        cwd=log.name.rsplit("/", 1)[0],
    )


def test_scheduler_and_worker_processes_on_localhost(tmp_path):
    """A real cluster: `dask scheduler` and `dask worker` as separate processes, the CLI as a third."""
    scheduler_file = tmp_path / "scheduler.json"
    with open(tmp_path / "scheduler.log", "w") as slog, open(tmp_path / "worker.log", "w") as wlog:
        scheduler = _spawn(
            [
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                str(scheduler_file),
            ],
            slog,
        )
        worker = None
        try:
            deadline = time.monotonic() + 60
            while not scheduler_file.exists() and time.monotonic() < deadline:
                assert scheduler.poll() is None, (tmp_path / "scheduler.log").read_text()
                time.sleep(0.2)
            address = json.loads(scheduler_file.read_text())["address"]
            assert address.startswith("tcp://127.0.0.1:")
            worker = _spawn(["worker", address, "--nthreads", "1", "--nworkers", "2", "--no-dashboard"], wlog)
            args = [
                "design",
                str(EXAMPLE),
                "--grid",
                "operation.altitude_m=0.5:5:0.5",
                "--grid",
                "water.attenuation_scale=0.5,1,1.5",
                "--grid",
                "light.beam_half_angle_deg=20,40",
                "--json",
            ]
            env = dict(os.environ, PYTHONPATH=str(ROOT))
            code, out, err = run(*args, "--dask", address, "--out", tmp_path / "remote.parquet", env=env, timeout_s=300)
            assert code == 0, err
            summary = json.loads(out)
            assert summary["points"] == 60 and summary["workers"] == 2
            code, _, err = run(*args, "--out", tmp_path / "here.parquet", env=env, timeout_s=300)
            assert code == 0, err
            assert parts_bytes(tmp_path / "remote.parquet") == parts_bytes(tmp_path / "here.parquet")
        finally:
            for process in (worker, scheduler):
                if process is not None:
                    process.terminate()
                    try:
                        process.wait(timeout=30)
                    except subprocess.TimeoutExpired:
                        process.kill()


def test_unreachable_scheduler_is_one_line(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr(cluster, "WORKER_TIMEOUT_S", 2)
    code = main(
        [
            "design",
            str(EXAMPLE),
            "--grid",
            "lens.f_number=2,4",
            "--dask",
            "tcp://127.0.0.1:9",
            "--out",
            str(tmp_path / "x.parquet"),
        ]
    )
    captured = capsys.readouterr()
    assert code == 2 and "127.0.0.1:9" in captured.err and captured.err.count("\n") == 1
    assert not (tmp_path / "x.parquet").exists()
