"""The dataset contract in-process: round trips, append-only parts and their merging, crash safety at every write,
file modes, the writer lock, refusal to overwrite, disk full, raw frames."""

import errno
import json
import os
import platform
import socket
import stat
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import scipy

import uwlab
from uwlab.errors import ConfigError
from uwlab.experiments import dataset_store
from uwlab.experiments.dataset import (
    POINT_SCHEMA,
    Dataset,
    DatasetLocked,
    DatasetWriteError,
    spectra_frame,
)
from uwlab.experiments.acquisition.dataset_check import check, repair
from uwlab.experiments.dataset_frames import read_frame
from uwlab.experiments.dataset_store import MANIFEST_FILE, MAX_LEVEL

PLAN = {"name": "unit", "sweep": [{"id": "a", "kind": "exposure", "values": {"start": 1, "stop": 400, "num": 400}}]}


def row(index: int, **extra) -> dict:
    base = {
        "sweep_id": "a",
        "point_index": index,
        "kind": "exposure",
        "frames": 2,
        "exposure_us": 10.0 * (index + 1),
        "mean_dn": 100.0 + index,
        "light_on": True,
        "frame_ids": [2 * index + 1, 2 * index + 2],
        "f_number": None,
        "irradiance_position": None,
    }
    return {**base, **extra}


def spectrum(index: int):
    return spectra_frame("a", index, [("target", np.array([400.0, 500.0]), np.array([0.1, 0.2]) * (index + 1))])


def test_create_append_open_round_trip(tmp_path):
    with Dataset.create(tmp_path / "d", PLAN, plan_sha256="abc", devices={"a": {"camera": {"model": "m"}}}) as data:
        data.append_point(row(0), spectrum(0))
        data.append_point(row(1))
    again = Dataset.open(tmp_path / "d")
    points = again.points()
    assert list(points.columns) == POINT_SCHEMA.names
    assert points["point_index"].tolist() == [0, 1]
    assert points["frame_ids"].map(list).tolist() == [[1, 2], [3, 4]]
    assert points["f_number"].isna().all() and points["irradiance_position"].isna().all()
    assert again.spectra()["irradiance_w_m2_nm"].tolist() == [0.1, 0.2]
    assert again.completed() == {("a", 0), ("a", 1)}
    meta = json.loads((tmp_path / "d" / "metadata.json").read_text())
    assert meta["plan"] == PLAN and meta["plan_sha256"] == "abc" and meta["finished_utc"] is None
    assert meta["devices"]["a"]["camera"]["model"] == "m"
    made_with = meta["provenance"]  # the versions and the machine, as their own sources give them
    assert made_with["packages"]["numpy"] == np.__version__ and made_with["packages"]["scipy"] == scipy.__version__
    assert made_with["packages"]["opencv-contrib-python-headless"].startswith(cv2.__version__)
    assert made_with["python"].startswith(platform.python_version()) and made_with["uwlab"] == uwlab.__version__
    if Path("/proc/cpuinfo").exists():
        assert made_with["cpu"] in Path("/proc/cpuinfo").read_text() and made_with["cpus"] == os.cpu_count()
    manifest = json.loads((tmp_path / "d" / MANIFEST_FILE).read_text())
    assert [p["tables"]["points"]["rows"] for p in manifest["parts"]] == [1, 1]
    first = tmp_path / "d" / manifest["parts"][0]["tables"]["points"]["file"]
    assert pq.read_table(first).num_rows == 1  # plain Parquet, readable by any tool
    assert check(again).ok


def test_files_follow_the_umask(tmp_path):
    old = os.umask(0o002)
    try:
        with Dataset.create(tmp_path / "d", PLAN, plan_sha256="abc") as data:
            data.append_point(row(0), spectrum(0))
    finally:
        os.umask(old)
    files = [p for p in (tmp_path / "d").rglob("*") if p.is_file()]
    assert len(files) == 7  # metadata and manifest (each with its backup copy), lock, a points and a spectra part
    assert {stat.S_IMODE(p.stat().st_mode) for p in files} == {0o664}


def test_parts_are_merged_keeping_order_and_rows(tmp_path, monkeypatch):
    monkeypatch.setattr(dataset_store, "FANOUT", 4)
    count = 4 * 4 + 4 + 3  # two merge levels, then a few single parts
    with Dataset.create(tmp_path, PLAN, plan_sha256="abc") as data:
        for index in range(count):
            data.append_point(row(index), spectrum(index) if index % 3 == 0 else None)
    store = Dataset.open(tmp_path).store
    assert [p.level for p in store.parts] == [2, 1] + [0] * 3
    named = {tmp_path / f.file for p in store.parts for f in p.tables.values()}
    assert set((tmp_path / "parts").iterdir()) == named  # merged files removed
    data = Dataset.open(tmp_path)
    assert data.points()["point_index"].tolist() == list(range(count))
    spectra = data.spectra()
    assert sorted(set(spectra["point_index"])) == list(range(0, count, 3))
    at_500 = spectra[spectra["wavelength_nm"] == 500.0]
    np.testing.assert_allclose(at_500["irradiance_w_m2_nm"], 0.2 * (at_500["point_index"] + 1))


def test_merging_stops_at_the_top_level(tmp_path, monkeypatch):
    monkeypatch.setattr(dataset_store, "FANOUT", 2)
    with Dataset.create(tmp_path, PLAN, plan_sha256="abc") as data:
        for index in range(2 * 2**MAX_LEVEL + 1):
            data.append_point(row(index))
    parts = Dataset.open(tmp_path).store.parts
    assert [(p.level, p.rows("points")) for p in parts] == [(MAX_LEVEL, 2**MAX_LEVEL)] * 2 + [(0, 1)]


class Crash(BaseException):
    """Stands for the process dying between two system calls."""


@pytest.mark.parametrize("crash_at", range(1, 44))
def test_a_crash_at_any_write_leaves_a_readable_dataset_that_resumes(tmp_path, monkeypatch, crash_at):
    """Six appends with FANOUT = 4 (a merge after the fourth) make 42 durable writes and renames (each manifest
    twice: the file and its backup copy); the process "dies" at the crash_at-th: the dataset reads back with a
    prefix of the points, passes its check, and resuming completes it (43: no crash)."""
    monkeypatch.setattr(dataset_store, "FANOUT", 4)
    calls = {"n": 0}

    def dying(real):
        def call(*args, **kwargs):
            calls["n"] += 1
            if calls["n"] == crash_at:
                raise Crash
            return real(*args, **kwargs)

        return call

    with Dataset.create(tmp_path, PLAN, plan_sha256="abc") as data:
        monkeypatch.setattr(dataset_store, "write_durable", dying(dataset_store.write_durable))
        monkeypatch.setattr(dataset_store.os, "replace", dying(os.replace))
        try:
            for index in range(6):
                data.append_point(row(index), spectrum(index))
        except Crash:
            pass
    monkeypatch.undo()
    assert calls["n"] == (crash_at if crash_at < 43 else 42)
    recorded = sorted(i for _, i in Dataset.open(tmp_path).completed())
    assert recorded == list(range(len(recorded)))
    with Dataset.open_for_writing(tmp_path) as data:
        report = check(data)
        if not report.ok:  # the crash came between a first manifest and its backup copy: named, and repaired
            assert [p.where for p in report.problems] == ["manifest.backup.json"], report.problems
            assert "missing" in report.problems[0].what
            repair(data)
            assert check(data).ok
        data.remove_strays()
        for index in range(len(recorded), 6):
            data.append_point(row(index), spectrum(index))
    final = Dataset.open(tmp_path)
    assert final.points()["point_index"].tolist() == list(range(6))
    assert sorted(set(final.spectra()["point_index"])) == list(range(6)) and not final.store.stray_files()


def test_existing_dataset_is_never_overwritten_without_force(tmp_path):
    with Dataset.create(tmp_path, PLAN, plan_sha256="abc") as data:
        data.append_point(row(0))
    with pytest.raises(ConfigError, match="--force"):
        Dataset.create(tmp_path, PLAN, plan_sha256="abc")
    assert len(Dataset.open(tmp_path).points()) == 1
    (tmp_path / "notes.txt").write_text("keep me")
    Dataset.create(tmp_path, PLAN, plan_sha256="new", force=True).close()
    assert Dataset.open(tmp_path).points().empty and Dataset.open(tmp_path).plan_sha256 == "new"
    assert (tmp_path / "notes.txt").read_text() == "keep me"


def test_a_dataset_with_nothing_recorded_is_replaced_without_force(tmp_path):
    Dataset.create(tmp_path, PLAN, plan_sha256="old").close()  # e.g. a sweep whose camera never opened
    with Dataset.create(tmp_path, PLAN, plan_sha256="new") as data:
        data.append_point(row(0))
    assert Dataset.open(tmp_path).plan_sha256 == "new"


def test_point_rows_are_checked(tmp_path):
    with Dataset.create(tmp_path, PLAN, plan_sha256="abc") as data:
        with pytest.raises(ConfigError, match="point.colour"):
            data.append_point(row(0, colour="red"))
        with pytest.raises(ConfigError, match="point.frames"):
            data.append_point(row(0, frames=1))
        for bad in (float("nan"), float("inf")):
            with pytest.raises(ConfigError, match="point.mean_dn.*finite"):
                data.append_point(row(0, mean_dn=bad))
        with pytest.raises(ConfigError, match="spectra"):
            data.append_point(row(0), spectrum(1))  # another point's spectra
        data.append_point(row(0))
        with pytest.raises(ConfigError, match="already recorded"):
            data.append_point(row(0))
    assert Dataset.open(tmp_path).completed() == {("a", 0)}


def test_readers_cannot_write(tmp_path):
    Dataset.create(tmp_path, PLAN, plan_sha256="abc").close()
    with pytest.raises(DatasetWriteError, match="open_for_writing"):
        Dataset.open(tmp_path).append_point(row(0))


def test_disk_full_keeps_what_was_recorded(tmp_path, monkeypatch):
    data = Dataset.create(tmp_path, PLAN, plan_sha256="abc")
    data.append_point(row(0), spectrum(0))
    real = dataset_store.write_durable

    def full(path, payload):
        if ".spectra." in path.name:
            raise OSError(errno.ENOSPC, "No space left on device")
        real(path, payload)

    monkeypatch.setattr(dataset_store, "write_durable", full)
    with pytest.raises(DatasetWriteError, match="No space left on device"):
        data.append_point(row(1), spectrum(1))
    monkeypatch.undo()
    assert Dataset.open(tmp_path).completed() == {("a", 0)}
    assert not [p for p in (tmp_path / "parts").iterdir() if ".spectra." in p.name and "00000002" in p.name]
    data.append_point(row(1), spectrum(1))
    assert Dataset.open(tmp_path).completed() == {("a", 0), ("a", 1)}
    data.close()


def test_the_parquet_reader_is_handed_no_python_object():
    """What a part's bytes are handed to Arrow's threaded Parquet reader as (`dataset_store.arrow_copy`) holds no
    Python object, so a reader thread that drops the last reference to it after the read (even while the interpreter
    shuts down) needs no GIL; a buffer over the Python bytes takes it there, and at exit that aborts the process.
    The bytes' reference count shows it: unchanged while the copy lives, one more while a buffer over them lives."""
    data = dataset_store.parquet_bytes([POINT_SCHEMA.empty_table()], POINT_SCHEMA)
    before = sys.getrefcount(data)
    source = dataset_store.arrow_copy(data)
    assert sys.getrefcount(data) == before
    assert source.to_pybytes() == data
    over_the_bytes = pa.py_buffer(data)  # the premise: a buffer over the bytes does show in the count
    assert sys.getrefcount(data) == before + 1
    del over_the_bytes


def test_one_writer_at_a_time_and_stale_locks_are_taken_over(tmp_path):
    data = Dataset.create(tmp_path, PLAN, plan_sha256="abc", purpose="first writer")
    with pytest.raises(DatasetLocked) as refused:
        Dataset.open_for_writing(tmp_path)
    message = str(refused.value)
    assert f"pid {os.getpid()} on host {socket.gethostname()}" in message and "first writer" in message
    assert len(message.splitlines()) == 1
    data.close()
    # a writer killed without releasing: its pid is dead, its lock file still names it
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    holder = {
        "host": socket.gethostname(),
        "pid": int(dead.stdout),
        "since_utc": "2024-01-01T00:00:00+00:00",
        "purpose": "killed",
    }
    (tmp_path / "lock").write_text(json.dumps(holder))
    with Dataset.open_for_writing(tmp_path) as taken:
        taken.append_point(row(0))
    # another host's lock cannot be judged from here: refused, naming the file to delete
    (tmp_path / "lock").write_text(json.dumps({**holder, "host": "other-host"}))
    with pytest.raises(DatasetLocked, match="other-host.*delete .*lock"):
        Dataset.open_for_writing(tmp_path)


def test_open_refuses_a_directory_that_is_not_a_dataset(tmp_path):
    with pytest.raises(ConfigError, match="not a dataset"):
        Dataset.open(tmp_path)
    with pytest.raises(ConfigError, match="not a dataset"):
        Dataset.open_for_writing(tmp_path)
    assert not (tmp_path / "lock").exists()


def test_finish_records_the_end_time(tmp_path):
    with Dataset.create(tmp_path, PLAN, plan_sha256="abc") as data:
        data.finish()
    assert Dataset.open(tmp_path).metadata["finished_utc"].startswith("20")


def test_raw_frames_are_committed_with_their_point(tmp_path):
    image = np.arange(12, dtype=np.uint16).reshape(3, 4)
    with Dataset.create(tmp_path, PLAN, plan_sha256="abc") as data:
        block = data.dark_block_recorder("a")
        block.add("dark", image + 1, {"exposure_us": 10.0})
        frames = data.frame_recorder("a", 0)
        frames.add("bright", image, {"exposure_us": 10.0, "settings": {"gain_db": None, "binning": (1, 1)}})
        frames.add("bright", image * 2, {"exposure_us": 10.0})
        frames.link_darks(block)
        assert not list((tmp_path / "frames" / "a").glob("0*"))  # nothing visible before the point is recorded
        data.append_point(row(0), frames=frames)
        unrecorded = data.frame_recorder("a", 1)
        unrecorded.add("bright", image, {})
        block.discard()
    found = Dataset.open(tmp_path).frames("a", 0)
    assert [p.name for p in found.bright] == ["bright-000.tiff", "bright-001.tiff"]
    assert [p.name for p in found.dark] == ["dark-000.tiff"]
    pixels, metadata = read_frame(found.bright[1])
    np.testing.assert_array_equal(pixels, image * 2)
    assert metadata == {"role": "bright", "number": 1, "exposure_us": 10.0}
    assert read_frame(found.bright[0])[1]["settings"] == {"gain_db": None, "binning": [1, 1]}
    np.testing.assert_array_equal(read_frame(found.dark[0])[0], image + 1)
    with pytest.raises(ConfigError, match="not recorded"):
        Dataset.open(tmp_path).frames("a", 1)
    with Dataset.open_for_writing(tmp_path) as data:
        data.remove_strays()  # the unrecorded point's staging folder goes, the recorded frames stay
    assert [p.name for p in (tmp_path / "frames" / "a").iterdir()] == ["00000"]
