"""Config and table files are read only when they are what they claim: regular, bounded, UTF-8, finite numbers.
Each bad file is one line naming the key and the file (the line too, for a value), exit code 2, no traceback,
no hang."""

from __future__ import annotations

import os
import shutil

import pytest

from tests.support.cli import one_line_error
from tests.support.paths import EXAMPLE
from uwlab.errors import ConfigError
from uwlab.model.data import MAX_TOML_BYTES, read_csv_columns, read_toml


def design_error(capsys, *args: str) -> str:
    return one_line_error(capsys, ["design", *args])


def test_a_fifo_as_config_is_refused_without_blocking(tmp_path, capsys):
    fifo = tmp_path / "design.toml"
    os.mkfifo(fifo)  # opening it for reading would block until a writer comes
    assert "not a regular file" in design_error(capsys, str(fifo))


def test_a_device_as_config_is_refused_before_reading(capsys):
    assert "not a regular file" in design_error(capsys, "/dev/zero")


def test_a_utf16_config_names_the_encoding(tmp_path, capsys):
    path = tmp_path / "design.toml"
    path.write_text(EXAMPLE.read_text(), encoding="utf-16")
    err = design_error(capsys, str(path))
    assert "not UTF-8" in err and "UTF-16" in err


def test_a_huge_config_is_refused_by_its_size(tmp_path):
    path = tmp_path / "design.toml"
    with open(path, "wb") as fh:
        fh.truncate(MAX_TOML_BYTES + 1)  # sparse: nothing is written or read
    with pytest.raises(ConfigError, match="larger than any TOML file"):
        read_toml(path)


def test_a_utf8_bom_is_accepted(tmp_path):
    path = tmp_path / "design.toml"
    path.write_bytes(b"\xef\xbb\xbf" + EXAMPLE.read_bytes())
    assert read_toml(path) == read_toml(EXAMPLE)


@pytest.mark.parametrize(
    "cell, words",
    [
        ("1e308", "not a finite number"),
        ("inf", "not a finite number"),
        ("nan", "not a finite number"),
        ("-1e20", "not a finite number"),
        ('"0,5"', "decimal comma"),
        ("abc", "is not a number"),
    ],
)
def test_a_bad_number_names_the_file_line_and_column(tmp_path, cell, words):
    path = tmp_path / "spectrum.csv"
    path.write_text(f"# a spectrum\nwavelength_nm,relative\n400,0.1\n500,{cell}\n600,0.3\n")
    with pytest.raises(ConfigError) as caught:
        read_csv_columns(path, ("wavelength_nm", "relative"), "light.spectrum")
    message = str(caught.value)
    assert words in message and "line 4" in message and "relative" in message and str(path) in message


def test_a_light_spectrum_of_1e308_is_refused_by_the_design(tmp_path, capsys):
    config = tmp_path / "design.toml"
    shutil.copy(EXAMPLE, config)
    (tmp_path / "huge.csv").write_text("wavelength_nm,relative\n400,1\n500,1e308\n600,1\n")
    err = design_error(capsys, str(config), "--set", "light.spectrum=huge.csv")
    assert "light.spectrum" in err and "line 3" in err


def test_good_tables_read_as_before(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("x,y\n3,30\n1,10\n2,20\n1,10\n")  # a row repeated exactly is read once
    table = read_csv_columns(path, ("x", "y"), "k")
    assert table["x"].tolist() == [1.0, 2.0, 3.0] and table["y"].tolist() == [10.0, 20.0, 30.0]


def test_a_wavelength_given_twice_with_two_values_is_refused(tmp_path):
    path = tmp_path / "spectrum.csv"
    path.write_text("# a spectrum\nwavelength_nm,relative\n600,0.3\n400,0.1\n500,0.2\n400,0.7\n")
    with pytest.raises(ConfigError) as caught:
        read_csv_columns(path, ("wavelength_nm", "relative"), "light.spectrum")
    message = str(caught.value)
    assert str(path) in message and "wavelength_nm = 400 is given twice" in message and "lines 4 and 6" in message


def test_a_duplicate_wavelength_in_a_design_spectrum_is_refused_in_one_line(tmp_path, capsys):
    config = tmp_path / "design.toml"
    shutil.copy(EXAMPLE, config)
    (tmp_path / "twice.csv").write_text("wavelength_nm,relative\n400,1\n500,0.5\n500,0.9\n600,1\n")
    err = design_error(capsys, str(config), "--set", "light.spectrum=twice.csv")
    assert "light.spectrum" in err and "twice.csv" in err and "wavelength_nm = 500 is given twice" in err, err


def test_a_duplicate_wavelength_in_a_jerlov_table_names_the_file_and_lines(tmp_path, monkeypatch):
    """The Jerlov table holds one spectrum per water type: a wavelength twice within one type is refused."""
    from uwlab.model.water import _jerlov_table

    (tmp_path / "water").mkdir()
    (tmp_path / "water" / "t.csv").write_text(
        "water_type,wavelength_nm,a_per_m,b_per_m\nI,400,0.1,0.2\nII,400,0.3,0.4\nI,500,0.1,0.2\nI,400,0.2,0.2\n"
    )
    with pytest.raises(ConfigError, match=r"wavelength_nm = 400 is given twice .*lines 2 and 5"):
        _jerlov_table(tmp_path, "t.csv")
