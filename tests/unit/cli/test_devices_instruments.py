"""`uwlab devices` lists VISA resources with their *IDN? (here pyvisa-sim's, from every shipped simulator YAML) and
serial ports, one line each, in the same JSON shape as the cameras; a VISA library that does not load is reported
in one line and the rest is still listed."""

from __future__ import annotations

import json

import pytest
import yaml

from tests.support.paths import CONFIGS
from uwlab.cli.main import main

SIMULATORS = sorted((CONFIGS / "instruments" / "sim").glob("*.yaml"))


def idn(path):
    """The *IDN? answer the simulator YAML gives (read from the file, not from the code under test)."""
    device = next(iter(yaml.safe_load(path.read_text())["devices"].values()))
    return next(d["r"] for d in device["dialogues"] if d["q"] == "*IDN?")


@pytest.mark.parametrize("path", SIMULATORS, ids=[p.stem for p in SIMULATORS])
def test_visa_resources_are_listed_with_their_identity(path, capsys):
    assert main(["devices", "--visa-library", f"{path}@sim", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert all(set(row) == {"backend", "id", "vendor", "model", "serial"} for row in rows)
    visa = [row for row in rows if row["backend"] == "visa"]
    maker, model, serial = idn(path).split(",")[:3]
    assert [(row["vendor"], row["model"], row["serial"]) for row in visa] == [(maker, model, serial)]
    resource = next(iter(yaml.safe_load(path.read_text())["resources"]))
    assert visa[0]["id"].split("::")[:3] == resource.split("::")[:3]


def test_one_line_each(capsys):
    path = SIMULATORS[0]
    assert main(["devices", "--visa-library", f"{path}@sim"]) == 0
    lines = capsys.readouterr().out.splitlines()
    visa = [line for line in lines if line.startswith("visa ")]
    assert len(visa) == 1 and idn(path).split(",")[1] in visa[0]
    assert all(line.split()[0] in ("sim", "visa", "serial", "aravis", "harvesters", "no") for line in lines)


@pytest.mark.parametrize(
    ("library", "cause"),
    [("no-visa.so", "cannot open shared object file"), ("no-such.yaml@sim", "file not found")],
)
def test_a_visa_library_that_does_not_load_is_one_line(tmp_path, capsys, library, cause):
    """Reported in one line saying why (pyvisa-sim packs a traceback into its error: the line gives its cause)."""
    assert main(["devices", "--visa-library", str(tmp_path / library), "--json"]) == 0
    captured = capsys.readouterr()
    [line] = [line for line in captured.err.splitlines() if "visa backend unavailable" in line]
    assert cause in line and "Traceback" not in line, line
    assert any(row["backend"] == "sim" for row in json.loads(captured.out))
