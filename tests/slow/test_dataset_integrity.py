"""Every byte of a dataset is checked: a flipped bit anywhere (parts, manifest, metadata, their copies) is repaired
or refused with one line, never read as another value, and --repair never sets aside an intact part."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from tests.support.bitflips import flip_campaign, small_dataset
from uwlab.errors import UwlabError
from uwlab.experiments.acquisition.dataset_check import check, repair
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.dataset_store import SEAL_KEY, backup_path
from uwlab.outputs import MANIFEST_FILE, METADATA_FILE


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    """A small recorded dataset (a simulated photon transfer: 24 points with spectra in 9 parts)."""
    return small_dataset(tmp_path_factory.mktemp("integrity") / "ds")


def test_metadata_and_manifest_are_sealed_and_kept_twice(pristine):
    for name in (METADATA_FILE, MANIFEST_FILE):
        text = (pristine / name).read_text()
        assert SEAL_KEY in json.loads(text)
        assert backup_path(pristine / name).read_text() == text


def test_a_changed_value_in_the_metadata_is_read_from_the_other_copy(pristine, tmp_path):
    """The issue's case: surround_reflectance 0.05 → 4.05 must not reach the fit."""
    copy = tmp_path / "ds"
    shutil.copytree(pristine, copy)
    text = (copy / METADATA_FILE).read_text()
    assert '"plan_sha256"' in text
    changed = text.replace('"plan_sha256": "', '"plan_sha256": "0', 1)
    (copy / METADATA_FILE).write_text(changed)
    dataset = Dataset.open(copy)
    assert dataset.metadata == Dataset.open(pristine).metadata
    report = check(dataset)
    assert not report.ok and report.problems[0].where == METADATA_FILE
    with Dataset.open_for_writing(copy) as writer:
        assert any("rewrote metadata.json" in line for line in repair(writer))
    assert check(Dataset.open(copy)).ok
    assert (copy / METADATA_FILE).read_text() == (pristine / METADATA_FILE).read_text()


def test_both_copies_damaged_is_one_line(pristine, tmp_path):
    copy = tmp_path / "ds"
    shutil.copytree(pristine, copy)
    for path in (copy / MANIFEST_FILE, backup_path(copy / MANIFEST_FILE)):
        path.write_text(path.read_text().replace('"next_id":', '"next_id":1', 1))
    with pytest.raises(UwlabError) as caught:
        Dataset.open(copy)
    assert "\n" not in str(caught.value) and MANIFEST_FILE in str(caught.value)


def test_a_dataset_written_before_seals_still_opens(pristine, tmp_path):
    copy = tmp_path / "ds"
    shutil.copytree(pristine, copy)
    for name in (METADATA_FILE, MANIFEST_FILE):
        document = json.loads((copy / name).read_text())
        del document[SEAL_KEY]
        (copy / name).write_text(json.dumps(document))
        backup_path(copy / name).unlink()
    assert Dataset.open(copy).points().equals(Dataset.open(pristine).points())


@pytest.mark.parametrize("seed", [2026, 2027])
def test_random_bit_flips_are_never_silent(pristine, tmp_path, seed):
    """60 random flips in all, as two campaigns of 30 (a test each, so that neither runs for a minute)."""
    outcomes = flip_campaign(pristine, tmp_path, trials=30, rng=np.random.default_rng(seed))
    assert outcomes.silent == []
    assert outcomes.lost_intact == []
    assert outcomes.unrepaired == []
    assert sum(outcomes.counts.values()) == 30
