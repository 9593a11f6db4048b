"""`dataset_check`: every kind of damage found and named (bit flips, duplicates, NaN, points outside the plan, missing
frames, a wrong finish time), repair sets aside without deleting, resume refuses a dataset that fails its check."""

import os
import random
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.sweep import open_for_resume
from uwlab.experiments.dataset import POINT_SCHEMA, Dataset, spectra_frame
from uwlab.experiments.acquisition.dataset_check import check, repair, summarize
from uwlab.experiments.dataset_store import PartDamaged

from tests.support.plans import write_plan

PLAN = {"name": "unit", "sweep": [{"id": "a", "kind": "exposure", "values": {"start": 1, "stop": 14, "num": 14}}]}


def row(index: int, sweep: str = "a", **extra) -> dict:
    return {
        "sweep_id": sweep,
        "point_index": index,
        "kind": "exposure",
        "frames": 2,
        "exposure_us": 10.0 * (index + 1),
        "mean_dn": 100.0 + index,
        "signal_dn": 90.0 + index,
        "saturated": False,
        **extra,
    }


def spectrum(index: int, sweep: str = "a"):
    nm = np.arange(380.0, 781.0, 5.0)
    return spectra_frame(sweep, index, [("target", nm, 1e-3 * (index + 1) * np.ones_like(nm))])


def dataset(root: Path, points: int = 10, plan: dict = PLAN, sha: str = "abc", sim: bool = False) -> Path:
    with Dataset.create(root, plan, plan_sha256=sha, sim=sim) as data:
        for index in range(points):
            data.append_point(row(index), spectrum(index))
    return root


def raw_append(root: Path, *rows: dict) -> None:
    """Rows written straight into the part store, past `append_point`'s rule (as another tool or a bug could)."""
    with Dataset.open_for_writing(root) as data:
        data.store.append({"points": pa.Table.from_pylist(list(rows), schema=POINT_SCHEMA)})


def flip(path: Path, bit: int) -> None:
    data = bytearray(path.read_bytes())
    data[bit // 8] ^= 1 << (bit % 8)
    path.write_bytes(bytes(data))


def test_a_sound_dataset_passes(tmp_path):
    report = check(Dataset.open(dataset(tmp_path)))
    assert report.ok and len(report.points) == 10 and report.totals == {"a": 14} and not report.strays


def test_every_single_bit_flip_in_a_part_file_is_detected(tmp_path):
    """300 random single-bit flips anywhere in the part files (data pages, headers, footers): every read of the
    flipped part fails, naming its file — none reads back as different values."""
    data = Dataset.open(dataset(tmp_path, points=20))
    rng = random.Random(1288)
    targets = [(part, name) for part in data.store.parts for name in part.tables]
    for _ in range(300):
        part, name = rng.choice(targets)
        path = tmp_path / part.tables[name].file
        bit = rng.randrange(path.stat().st_size * 8)
        flip(path, bit)
        with pytest.raises(PartDamaged) as damaged:
            data.store.read(part, name)
        assert damaged.value.file == part.tables[name].file
        flip(path, bit)
    part, name = targets[0]
    flip(tmp_path / part.tables[name].file, 8 * 100 + 3)
    report = check(Dataset.open(tmp_path))
    assert not report.ok and part.tables[name].file in report.summary_line() and report.damaged_parts == {part.id}


def _page_flips(path: Path, rng: random.Random, count: int) -> tuple[int, int]:
    """(errors, silently different reads) of ``count`` single-bit flips inside the column chunks (pages) of a
    Parquet file read by pyarrow alone with page checksum verification."""
    original = path.read_bytes()
    meta = pq.ParquetFile(path).metadata
    spans = []
    for g in range(meta.num_row_groups):
        for c in range(meta.num_columns):
            chunk = meta.row_group(g).column(c)
            start = min(o for o in (chunk.dictionary_page_offset, chunk.data_page_offset) if o is not None)
            spans.append((start, start + chunk.total_compressed_size))
    expected = pq.read_table(path)
    errors = silent = 0
    for _ in range(count):
        start, stop = rng.choice(spans)
        bit = rng.randrange(start * 8, stop * 8)
        data = bytearray(original)
        data[bit // 8] ^= 1 << (bit % 8)
        try:
            table = pq.read_table(pa.BufferReader(bytes(data)), page_checksum_verification=True)
        except (OSError, pa.ArrowException):
            errors += 1
            continue
        silent += not table.equals(expected)
    return errors, silent


def test_parquet_page_checksums_catch_flips_for_any_reader(tmp_path):
    """The part files carry Parquet page checksums: pyarrow alone, verifying them, never returns silently changed
    values after a flip in a page. The same table written without checksums does (the dataset format before)."""
    data = Dataset.open(dataset(tmp_path, points=3))
    path = tmp_path / data.store.parts[0].tables["spectra"].file
    rng = random.Random(16)
    errors, silent = _page_flips(path, rng, 300)
    assert silent == 0 and errors > 200  # the others flip bits no value depends on (page statistics, padding)
    plain = tmp_path / "plain.parquet"
    pq.write_table(pq.read_table(path), plain)
    assert _page_flips(plain, rng, 300)[1] > 0


def test_resume_refuses_a_damaged_dataset_and_repair_keeps_the_intact_points(tmp_path):
    sweep = {"id": "a", "kind": "exposure", "values": {"start": 100, "stop": 1400, "num": 14}, "dark": "none"}
    plan = load_plan(write_plan(tmp_path / "plan.toml", None, [sweep]))
    root = dataset(tmp_path / "d", points=20 - 6, plan=plan.raw, sha=plan.sha256, sim=True)
    data = Dataset.open(root)
    damaged = data.store.parts[-1]  # the last point's part
    flip(root / damaged.tables["spectra"].file, 8 * 200)
    with pytest.raises(ConfigError, match="fails its check.*--repair"):
        open_for_resume(root, plan, sim=True)
    with Dataset.open_for_writing(root) as writer:
        actions = repair(writer)
    assert any("damaged" in action for action in actions)
    quarantined = [p.name for p in (root / "quarantine").rglob("*.parquet")]
    assert Path(damaged.tables["spectra"].file).name in quarantined  # set aside, not deleted
    report = check(Dataset.open(root))
    assert report.ok and sorted(report.points["point_index"]) == list(range(13))  # 13 intact points kept
    with open_for_resume(root, plan, sim=True) as resumed:
        assert resumed.completed() == {("a", i) for i in range(13)}


def test_duplicates_nan_and_points_outside_the_plan_are_reported_and_set_aside(tmp_path):
    root = dataset(tmp_path, points=5)
    raw_append(root, row(2), row(7, mean_dn=float("nan")), row(40), row(1, sweep="b"))
    with Dataset.open_for_writing(root) as writer:
        writer.update_metadata(finished_utc="2024-01-01T00:00:00+00:00")
    report = check(Dataset.open(root))
    problems = "\n".join(map(str, report.problems))
    assert "point a#2: recorded 2 times" in problems
    assert "point a#7: point.mean_dn = nan: must be a finite number" in problems
    assert "point a#40: not in the plan (sweep 'a' has 14 points)" in problems
    assert "point b#1: not in the plan (no sweep 'b')" in problems
    assert "finished_utc is set" in problems
    summary = summarize(Dataset.open(root))
    assert summary["state"] == "damaged" and summary["points_done"] == 4 and summary["points_total"] == 14  # 0, 1, 3, 4
    assert summary["finished_utc"] and len(summary["problems"]) == len(report.problems)
    with Dataset.open_for_writing(root) as writer:
        repair(writer)
    after = Dataset.open(root)
    assert check(after).ok and sorted(after.points()["point_index"]) == [0, 1, 3, 4]
    assert after.metadata["finished_utc"] is None
    assert sorted(set(after.spectra()["point_index"])) == [0, 1, 3, 4]
    assert len(list((root / "quarantine").rglob("*.parquet"))) >= 2


def test_points_of_save_frames_sweeps_need_their_frames(tmp_path):
    plan = {"sweep": [{"id": "a", "kind": "exposure", "values": [1, 2], "save_frames": True}]}
    image = np.zeros((2, 2), np.uint16)
    with Dataset.create(tmp_path, plan, plan_sha256="abc") as data:
        for index in range(2):
            frames = data.frame_recorder("a", index)
            for _ in range(2):
                frames.add("bright", image, {})
            data.append_point(row(index, dark_frames=0), frames=frames)
    assert check(Dataset.open(tmp_path)).ok
    Dataset.open(tmp_path).frames("a", 1).bright[0].unlink()
    report = check(Dataset.open(tmp_path))
    assert [str(p) for p in report.problems] == [
        "point a#1: has 1/2 bright and 0/0 dark frames stored (save_frames = true)"
    ]
    with Dataset.open_for_writing(tmp_path) as writer:
        repair(writer)
    assert Dataset.open(tmp_path).completed() == {("a", 0)}
    assert list((tmp_path / "quarantine").rglob("bright-001.tiff"))  # the remaining frame set aside with it


@pytest.mark.parametrize("name", ["manifest.backup.json", "metadata.backup.json"])
@pytest.mark.parametrize("damage", ["bit flip", "truncation", "deletion", "fifo"])
def test_a_damaged_backup_copy_is_named_by_check_and_rewritten_by_repair(tmp_path, capsys, name, damage):
    """The second copy is checked too: damage to it alone fails `uwlab dataset check` naming it (the dataset still
    reads from the intact file), and --repair writes it again, byte for byte the copy it was."""
    from uwlab.cli.main import main

    root = dataset(tmp_path / "ds")
    backup = root / name
    original = backup.read_bytes()
    if damage == "bit flip":
        flip(backup, 8 * (len(original) // 2) + 3)
    elif damage == "truncation":
        backup.write_bytes(original[: len(original) // 3])
    else:
        backup.unlink()
        if damage == "fifo":
            os.mkfifo(backup)
    assert Dataset.open(root).metadata["plan_sha256"] == "abc"
    assert main(["dataset", "check", str(root)]) == 1
    out = capsys.readouterr().out
    assert f"problem: {name}: is {'missing' if damage == 'deletion' else 'damaged'}" in out, out
    assert main(["dataset", "check", str(root), "--repair"]) == 0
    out = capsys.readouterr().out
    assert f"rewrote {name}" in out and ": ok;" in out, out
    assert backup.read_bytes() == original
    assert main(["dataset", "check", str(root)]) == 0


@pytest.mark.timeout(60)
def test_a_part_file_replaced_by_a_fifo_is_damaged_not_waited_on(tmp_path):
    root = dataset(tmp_path / "ds", points=3)
    part = sorted((root / "parts").glob("*.points.parquet"))[0]
    part.unlink()
    os.mkfifo(part)
    report = check(Dataset.open(root))
    problem = report.problems[0]
    assert not report.ok and problem.where == f"parts/{part.name}" and "not a regular file" in problem.what, problem
