"""Outputs never go inside a uwlab dataset (a folder holding metadata.json and manifest.json)."""

from __future__ import annotations

import pytest

from uwlab.errors import ConfigError
from uwlab.outputs import (
    FIT_FOLDER,
    MANIFEST_FILE,
    REPORT_FILE,
    METADATA_FILE,
    dataset_holding,
    output_dir,
    output_file,
)


@pytest.fixture
def dataset(tmp_path):
    root = tmp_path / "ds"
    (root / "parts").mkdir(parents=True)
    (root / METADATA_FILE).write_text("{}")
    (root / MANIFEST_FILE).write_text("{}")
    return root


@pytest.mark.parametrize("inside", ["parts", "new", "parts/deeper"])
def test_a_directory_inside_a_dataset_is_refused(dataset, inside):
    with pytest.raises(ConfigError, match="inside the dataset"):
        output_dir(dataset / inside, "--out")


def test_a_file_inside_a_dataset_is_refused_even_through_a_link(dataset, tmp_path):
    (tmp_path / "link").symlink_to(dataset / "parts")
    for path in (dataset / "notes.html", tmp_path / "link" / "report.html"):
        with pytest.raises(ConfigError, match="inside the dataset"):
            output_file(path, "--out")


def test_beside_a_dataset_and_a_half_marked_folder_are_fine(dataset, tmp_path):
    assert output_dir(tmp_path / "fit", "--out") == tmp_path / "fit"
    half = tmp_path / "half"
    half.mkdir()
    (half / METADATA_FILE).write_text("{}")
    assert dataset_holding(half / "x") is None
    assert dataset_holding(dataset / "parts" / "x") == dataset.resolve()


def test_the_default_fit_folder_and_report_are_the_only_outputs_inside_a_dataset(dataset):
    # `uwlab fit DATASET` writes DATASET/fit, `uwlab report DATASET` DATASET/report.html (documented defaults)
    assert output_file(dataset / REPORT_FILE, "--out") == dataset / REPORT_FILE
    assert output_dir(dataset / FIT_FOLDER, "--out") == dataset / FIT_FOLDER
    (dataset / FIT_FOLDER).mkdir()
    assert output_file(dataset / FIT_FOLDER / "corner.png", "--out") == dataset / FIT_FOLDER / "corner.png"
    with pytest.raises(ConfigError, match="inside the dataset"):
        output_dir(dataset / "fitted", "--out")
