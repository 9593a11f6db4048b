"""A Sekonic C-7000 export written under a decimal-comma locale: read exactly when its separator makes the numbers
unambiguous (semicolons), refused in one line otherwise — never imported as the integer parts (an all-zero
spectrum, as before)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.support.paths import DATA
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.spectra import read_sekonic_csv

SAMPLE = DATA / "sekonic_c7000_synthetic.csv"


def _localised(text: str, separator: str) -> str:
    lines = []
    for line in text.splitlines():
        if line.startswith("Spectral Data"):
            label, value = line.split(",")
            line = f"{label}{separator}{value.replace('.', ',')}"
        lines.append(line)
    return "\n".join(lines) + "\n"


def test_semicolons_and_decimal_commas_read_as_the_original(tmp_path):
    path = tmp_path / "comma.csv"
    path.write_text(_localised(SAMPLE.read_text(), ";"))
    wavelength, irradiance = read_sekonic_csv(path)
    expected = read_sekonic_csv(SAMPLE)
    np.testing.assert_array_equal(wavelength, expected[0])
    np.testing.assert_array_equal(irradiance, expected[1])
    assert irradiance.min() > 0


def test_decimal_commas_in_a_comma_separated_file_are_refused_naming_the_line(tmp_path):
    path = tmp_path / "ambiguous.csv"
    path.write_text(_localised(SAMPLE.read_text(), ","))
    with pytest.raises(ConfigError, match=r"line 10 .*decimal comma"):
        read_sekonic_csv(path)
