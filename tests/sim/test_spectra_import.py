"""Sekonic C-7000 CSV import refuses what it cannot trust, naming the line: strays, out-of-range wavelengths and
values, gaps, repeats, short files. The sample is `tests/sim/data/sekonic_c7000_synthetic.csv` (a 5 nm block on
lines 10–90, a 1 nm block on lines 92–492, both 380–780 nm)."""

from pathlib import Path

import numpy as np
import pytest

from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.spectra import read_sekonic_csv

from tests.support.cli_process import run
from tests.support.paths import DATA

SAMPLE = DATA / "sekonic_c7000_synthetic.csv"
LINES = SAMPLE.read_text().splitlines()
ONE_NM = {
    int(line.split()[2].split("[")[0]): number
    for number, line in enumerate(LINES, start=1)
    if line.startswith("Spectral Data") and number >= 92
}


def edited(tmp_path, lines) -> Path:
    path = tmp_path / "edited.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def replaced(number: int, text: str) -> list[str]:
    return LINES[: number - 1] + [text] + LINES[number:]


CASES = {
    # name: (lines of the file, the line the refusal must name, words of the reason)
    "stray row at 99999 nm": (LINES + ["Spectral Data 99999[nm],5"], len(LINES) + 1, "outside"),
    "row at 0 nm": (replaced(ONE_NM[450], "Spectral Data 0[nm],0.0004"), ONE_NM[450], "outside"),
    "negative value": (replaced(ONE_NM[600], "Spectral Data 600[nm],-0.001"), ONE_NM[600], "outside [0"),
    "1e308": (replaced(ONE_NM[700], "Spectral Data 700[nm],1e308"), ONE_NM[700], "outside [0"),
    "not a number": (replaced(ONE_NM[520], "Spectral Data 520[nm],abc"), ONE_NM[520], "must be numbers"),
    "missing 500-599 nm": (
        [line for n, line in enumerate(LINES, start=1) if n not in range(ONE_NM[500], ONE_NM[599] + 1)],
        ONE_NM[500],
        "missing 500–599 nm",
    ),
    "repeated row": (
        LINES[: ONE_NM[455]] + [LINES[ONE_NM[455] - 1]] + LINES[ONE_NM[455] :],
        ONE_NM[455] + 1,
        "must increase",
    ),
    "three rows": (LINES[:9] + LINES[91:94], 12, "ends at 382 nm"),
    "second 1 nm block": (LINES + LINES[91:], len(LINES) + 1, "a second 1 nm block"),
    "block not from 380 nm": (LINES[:9] + LINES[101:], 10, "starts at 390 nm"),
}


@pytest.mark.parametrize("name", CASES)
def test_untrustworthy_files_are_refused_naming_the_line(tmp_path, name):
    lines, line, reason = CASES[name]
    path = edited(tmp_path, lines)
    with pytest.raises(ConfigError) as refused:
        read_sekonic_csv(path)
    message = str(refused.value)
    assert refused.value.key == "import" and str(path) in message and len(message.splitlines()) == 1
    assert f"line {line}" in message and reason in message


def test_the_untouched_sample_still_imports():
    wavelength_nm, irradiance = read_sekonic_csv(SAMPLE)
    np.testing.assert_array_equal(wavelength_nm, np.arange(380.0, 781.0))
    assert (irradiance > 0).all()


def test_a_lone_5_nm_block_is_used(tmp_path):
    wavelength_nm, _ = read_sekonic_csv(edited(tmp_path, LINES[:90]))
    np.testing.assert_array_equal(wavelength_nm, np.arange(380.0, 781.0, 5.0))


@pytest.mark.parametrize("name", ["stray row at 99999 nm", "three rows"])
def test_the_cli_refuses_in_one_line_with_exit_2(tmp_path, name):
    lines, line, _ = CASES[name]
    path = edited(tmp_path, lines)
    code, out, err = run("spectrum", "--import", path, "--json", timeout_s=120)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and f"line {line}" in err
