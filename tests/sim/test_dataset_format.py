"""The dataset contract: create/open round trips, atomic appends, refusal to overwrite, ENOSPC."""
import errno
import json

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from uwlab.errors import ConfigError
from uwlab.experiments import dataset as ds
from uwlab.experiments.dataset import POINT_SCHEMA, Dataset, DatasetWriteError, spectra_frame

PLAN = {"name": "unit", "sweep": [{"id": "a", "kind": "exposure", "values": [10.0, 20.0]}]}


def row(index: int, **extra) -> dict:
    base = {"sweep_id": "a", "point_index": index, "kind": "exposure", "frames": 2, "exposure_us": 10.0 * (index + 1),
            "mean_dn": 100.0 + index, "light_on": True, "frame_ids": [2 * index + 1, 2 * index + 2],
            "f_number": None, "irradiance_position": None}
    return {**base, **extra}


def test_create_append_open_round_trip(tmp_path):
    data = Dataset.create(tmp_path / "d", PLAN, plan_sha256="abc", devices={"a": {"camera": {"model": "m"}}})
    spectra = spectra_frame("a", 0, [("target", np.array([400.0, 500.0]), np.array([0.1, 0.2]))])
    data.append_point(row(0), spectra)
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
    assert meta["devices"]["a"]["camera"]["model"] == "m" and "numpy" in meta["software"]
    assert pq.read_table(tmp_path / "d" / "points.parquet").num_rows == 2


def test_existing_dataset_is_never_overwritten_without_force(tmp_path):
    Dataset.create(tmp_path, PLAN, plan_sha256="abc").append_point(row(0))
    with pytest.raises(ConfigError, match="--force"):
        Dataset.create(tmp_path, PLAN, plan_sha256="abc")
    assert len(Dataset.open(tmp_path).points()) == 1
    (tmp_path / "notes.txt").write_text("keep me")
    Dataset.create(tmp_path, PLAN, plan_sha256="new", force=True)
    assert Dataset.open(tmp_path).points().empty and Dataset.open(tmp_path).plan_sha256 == "new"
    assert (tmp_path / "notes.txt").read_text() == "keep me"


def test_point_rows_are_checked(tmp_path):
    data = Dataset.create(tmp_path, PLAN, plan_sha256="abc")
    with pytest.raises(ConfigError, match="point.colour"):
        data.append_point(row(0, colour="red"))
    with pytest.raises(ConfigError, match="point.frames"):
        data.append_point(row(0, frames=1))
    data.append_point(row(0))
    with pytest.raises(ConfigError, match="already recorded"):
        data.append_point(row(0))


def test_spectra_of_an_unfinished_point_are_dropped_and_replaced(tmp_path):
    Dataset.create(tmp_path, PLAN, plan_sha256="abc")
    stale = spectra_frame("a", 0, [("camera", [400.0], [9.0])])  # a crash after the spectra, before the point
    pq.write_table(pa.Table.from_pandas(stale, schema=ds.SPECTRA_SCHEMA, preserve_index=False),
                   tmp_path / "spectra.parquet")
    data = Dataset.open(tmp_path)
    assert data.spectra().empty
    data.append_point(row(0), spectra_frame("a", 0, [("camera", [400.0], [1.0])]))
    assert Dataset.open(tmp_path).spectra()["irradiance_w_m2_nm"].tolist() == [1.0]


def test_disk_full_keeps_what_was_recorded(tmp_path, monkeypatch):
    data = Dataset.create(tmp_path, PLAN, plan_sha256="abc")
    data.append_point(row(0))

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(ds.pq, "write_table", full)
    with pytest.raises(DatasetWriteError, match="No space left on device"):
        data.append_point(row(1))
    monkeypatch.undo()
    assert Dataset.open(tmp_path).completed() == {("a", 0)}
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    data.append_point(row(1))
    assert Dataset.open(tmp_path).completed() == {("a", 0), ("a", 1)}


def test_open_refuses_a_directory_that_is_not_a_dataset(tmp_path):
    with pytest.raises(ConfigError, match="not a dataset"):
        Dataset.open(tmp_path)


def test_finish_records_the_end_time(tmp_path):
    data = Dataset.create(tmp_path, PLAN, plan_sha256="abc")
    data.finish()
    assert isinstance(pd.Timestamp(Dataset.open(tmp_path).metadata["finished_utc"]), pd.Timestamp)
