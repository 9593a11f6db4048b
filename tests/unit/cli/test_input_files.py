"""Every command that reads a file reads it through one bounded regular-file reader (`uwlab.model.data.read_bytes`,
`check_input_file` for paths a library opens): a FIFO (opening it for reading would block for ever), a device
(`/dev/zero` would be read until memory runs out), a directory or an over-size file is refused in one line naming
the option and the file, exit code 2, no traceback — never waited on or read. The timeout marks turn a hang (the
defect) into a failure instead of a stuck suite; nothing here measures time."""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import tifffile

from tests.support.cli import one_line_error
from tests.support.paths import CONFIGS, DATA
from uwlab.errors import ConfigError
from uwlab.model.data import MAX_BINARY_BYTES, MAX_CSV_BYTES, check_input_file, read_bytes

DOME = CONFIGS / "design" / "dome-8mm.toml"
LAMP = DATA / "ocean_insight_lamp_3100k.LMP"
# a VISA supply on its pyvisa-sim twin (configs/instruments/sim/)
SUPPLY = ["--instrument", "scpi-dc-supply", "--resource", "TCPIP0::192.168.0.10::inst0::INSTR"]
SIM_SPECTRUM = ["spectrum", "--instrument", "ocean-insight", "--sim"]
SIM_SUPPLY = [*SUPPLY, "--visa-library", f"{CONFIGS / 'instruments' / 'sim' / 'scpi-dc-supply.yaml'}@sim"]


def calibrate(tmp: Path) -> list[str]:
    return ["spectrometer", "calibrate", "--out-csv", str(tmp / "calibration.csv")]


# (name, suffix of the file, argv with the file in it)
COMMANDS: list[tuple[str, str, Callable[[Path, Path], list[str]]]] = [
    ("design", ".toml", lambda f, tmp: ["design", str(f)]),
    ("sweep plan", ".toml", lambda f, tmp: ["sweep", str(f), "--sim", "--out", str(tmp / "dataset")]),
    ("spectrum --import", ".csv", lambda f, tmp: ["spectrum", "--import", str(f)]),
    ("emva --descriptor", ".txt", lambda f, tmp: ["emva", "characterize", "--descriptor", str(f)]),
    ("emva --irradiance", ".csv", lambda f, tmp: ["emva", "characterize", str(tmp), "--irradiance", str(f)]),
    ("port --board", ".toml", lambda f, tmp: ["port", "board", "--board", str(f), "--out", str(tmp / "b.png")]),
    ("port trace", ".toml", lambda f, tmp: ["port", "trace", str(f)]),
    ("grab --config", ".toml", lambda f, tmp: ["grab", "--config", str(f)]),
    ("devices --config", ".toml", lambda f, tmp: ["devices", "--config", str(f)]),
    ("mtf IMAGE", ".tif", lambda f, tmp: ["mtf", str(f)]),
    ("spectrum --calibration", ".cal", lambda f, tmp: [*SIM_SPECTRUM, "--calibration", str(f)]),
    ("spectrum --dark", ".csv", lambda f, tmp: [*SIM_SPECTRUM, "--dark", str(f)]),
    ("spectrometer --lamp", ".LMP", lambda f, tmp: [*calibrate(tmp), "--sim", "--lamp", str(f)]),
    (
        "spectrometer --lamp-spectrum",
        ".txt",
        lambda f, tmp: [
            *(*calibrate(tmp), "--lamp", str(LAMP), "--lamp-spectrum", str(f)),
            *("--dark-spectrum", str(DATA / "spectrasuite_dark_FLMS01234.txt")),
        ],
    ),
    ("light --rig", ".toml", lambda f, tmp: ["light", *SIM_SUPPLY, "--rig", str(f)]),
    ("light --visa-library PATH@sim", ".yaml", lambda f, tmp: ["light", *SUPPLY, "--visa-library", f"{f}@sim"]),
    (
        "light calibrate --calibration",
        ".csv",
        lambda f, tmp: [
            *("light", "calibrate", "--light", "/dev/null", "--spectrometer-instrument", "ocean-insight"),
            *("--calibration", str(f), "--out", str(tmp / "out.csv")),
        ],
    ),
    (
        "light --instrument FILE",
        ".toml",
        lambda f, tmp: ["light", "--instrument", str(f), "--resource", "ASRL1::INSTR"],
    ),
    (  # the light's files are checked before the spectrometer (a port that cannot be opened) is opened
        "light calibrate --instrument FILE",
        ".toml",
        lambda f, tmp: [
            *("light", "calibrate", "--instrument", str(f), "--resource", "ASRL1::INSTR"),
            *("--spectrometer", "/dev/null", "--out", str(tmp / "out.csv")),
        ],
    ),
    (
        "light calibrate --visa-library PATH@sim",
        ".yaml",
        lambda f, tmp: [
            *("light", "calibrate", *SUPPLY, "--visa-library", f"{f}@sim"),
            *("--spectrometer", "/dev/null", "--out", str(tmp / "out.csv")),
        ],
    ),
    ("sim camera --rig-state", ".json", lambda f, tmp: ["sim", "camera", "--gige", "--rig-state", str(f)]),
    (
        "sim charuco --board",
        ".toml",
        lambda f, tmp: ["sim", "charuco", str(DOME), "--medium", "air", "--out", str(tmp / "o"), "--board", str(f)],
    ),
]


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _sparse(path: Path) -> Path:
    """A file larger than any input cap, images' included (sparse: no disk is used)."""
    with open(path, "wb") as fh:
        fh.truncate(max(MAX_CSV_BYTES, MAX_BINARY_BYTES) + 1)
    return path


def _directory(path: Path) -> Path:
    path.mkdir()
    return path


BAD_FILES = {
    "fifo": (_fifo, "not a regular file"),
    "device": (lambda path: Path("/dev/zero"), "not a regular file"),
    "directory": (_directory, "is a directory"),
    "over-size": (_sparse, "larger than any"),
}


@pytest.mark.timeout(60)
@pytest.mark.parametrize("bad", BAD_FILES)
@pytest.mark.parametrize(("command", "suffix", "argv"), COMMANDS, ids=[c[0] for c in COMMANDS])
def test_a_non_regular_or_over_size_input_is_refused_in_one_line(tmp_path, capsys, command, suffix, argv, bad):
    make, words = BAD_FILES[bad]
    path = make(tmp_path / f"input{suffix}")
    err = one_line_error(capsys, argv(path, tmp_path))
    assert words in err and str(path) in err, err


@pytest.mark.timeout(60)
def test_a_fifo_among_the_images_of_a_port_calibration_is_refused(tmp_path, capsys):
    (tmp_path / "air").mkdir()
    (tmp_path / "water").mkdir()
    fifo = _fifo(tmp_path / "air" / "view.png")
    design = Path(__file__).resolve().parents[3] / "configs" / "design" / "example.toml"
    folders = [str(tmp_path / "air"), str(tmp_path / "water")]
    err = one_line_error(capsys, ["port", "calibrate", *folders, "--port", "flat", "--config", str(design)])
    assert "not a regular file" in err and str(fifo) in err and "an image file" in err, err


@pytest.mark.timeout(60)
@pytest.mark.parametrize("bad", ["fifo", "device"])
def test_an_image_of_a_descriptor_that_is_not_a_regular_file_is_refused(tmp_path, capsys, bad):
    for name, value in (("a.tif", 100), ("c.tif", 10), ("d.tif", 11)):
        tifffile.imwrite(tmp_path / name, np.full((8, 8), value, np.uint16))
    if bad == "fifo":
        _fifo(tmp_path / "b.tif")
    else:
        (tmp_path / "b.tif").symlink_to("/dev/zero")
    descriptor = tmp_path / "d.txt"
    descriptor.write_text("v 4.0\nn 12 8 8\nb 1000 10\ni a.tif\ni b.tif\nd 1000\ni c.tif\ni d.tif\n")
    err = one_line_error(capsys, ["emva", "characterize", "--descriptor", str(descriptor)])
    assert "not a regular file" in err and "b.tif" in err, err


@pytest.mark.timeout(60)
def test_a_fifo_in_a_report_folder_is_refused(tmp_path, capsys):
    """`uwlab report` reads the fit directories it finds: a summary.json that is a FIFO is refused, not waited on."""
    fit = tmp_path / "fit"
    fit.mkdir()
    (fit / "samples.parquet").write_bytes(b"")
    _fifo(fit / "summary.json")
    err = one_line_error(capsys, ["report", str(tmp_path)])
    assert "not a regular file" in err and "summary.json" in err, err


def test_the_reader_reads_no_more_than_its_cap_whatever_the_size_says(tmp_path):
    """`read_bytes` returns a regular file whole, and refuses one beyond its cap by its size before reading."""
    path = tmp_path / "table.csv"
    shutil.copy(Path(__file__).resolve().parents[2] / "data" / "sekonic_c7000_synthetic.csv", path)
    data = path.read_bytes()
    assert read_bytes(path, "k", len(data), "CSV") == data
    with pytest.raises(ConfigError, match=f"{len(data)} bytes: larger than any CSV file"):
        read_bytes(path, "k", len(data) - 1, "CSV")
    assert check_input_file(path, "k", len(data), "CSV") == path
    with pytest.raises(ConfigError, match="file not found"):
        check_input_file(tmp_path / "missing.tif", "image", 10, "image")


@pytest.mark.timeout(60)
def test_a_fifo_given_as_a_gentl_producer_is_refused(tmp_path):
    from uwlab.drivers.camera.harvesters_backend import cti_files

    fifo = _fifo(tmp_path / "producer.cti")
    with pytest.raises(ConfigError, match="not a regular file"):
        cti_files([str(fifo)])
    (tmp_path / "real.cti").write_bytes(b"\0")  # a folder gives its regular *.cti files only
    assert cti_files([str(tmp_path)]) == [tmp_path / "real.cti"]


@pytest.mark.timeout(60)
def test_a_fifo_as_the_shared_light_state_is_not_waited_on(tmp_path):
    """`uwlab sim camera --rig-state FILE` reads the light state at every frame: a FIFO there is refused (the state
    held in memory is used), never opened."""
    from uwlab.sim.rig_state import LightState, RigState

    state = RigState(_fifo(tmp_path / "state.json"))
    assert state.light == LightState()


@pytest.mark.timeout(60)
@pytest.mark.parametrize("bad", ["fifo", "device"])
def test_a_lock_file_that_is_not_a_regular_file_is_refused_not_waited_on(tmp_path, bad):
    """A FIFO planted as a dataset's or a rig folder's lock is refused in one line when the lock is taken (opening
    it non-blocking; reading its holder would wait for ever), and is no holder; a lock beyond a holder record's size
    is read no further and names no holder."""
    from uwlab.lockfile import MAX_HOLDER_BYTES, OwnerLock, is_stale, read_holder

    lock = _fifo(tmp_path / "lock") if bad == "fifo" else Path("/dev/zero")
    with pytest.raises(ConfigError, match="not a regular file .*not a lock file"):
        OwnerLock(lock, "test").acquire()
    assert read_holder(lock) is None and not is_stale(lock)
    big = _sparse(tmp_path / "big-lock")
    assert big.stat().st_size > MAX_HOLDER_BYTES and read_holder(big) is None
    with OwnerLock(big, "test"):  # not a holder: a free lock, taken over (and rewritten)
        assert read_holder(big).pid == os.getpid()


@pytest.mark.timeout(60)
def test_a_fifo_as_a_simulators_state_log_is_neither_waited_on_nor_read(tmp_path):
    """Appending to a FIFO with no reader fails at once (O_NONBLOCK) instead of stalling the simulated instrument;
    reading the log goes through the bounded reader."""
    from uwlab.sim.state_log import StateLog

    log = StateLog(_fifo(tmp_path / "light.state.jsonl"))
    with pytest.raises(OSError):
        log.append("command", on=True)
    with pytest.raises(ConfigError, match="not a regular file"):
        log.entries()
    regular = StateLog(tmp_path / "spectrometer.state.jsonl")
    assert regular.entries() == []
    regular.append("read", level=0.5)
    assert [e["level"] for e in regular.entries()] == [0.5]


def test_a_malformed_pyvisa_sim_file_is_one_line(tmp_path, capsys):
    """pyvisa-sim re-raises the YAML parser's error twice, each with the last traceback packed in its message: the
    line gives the parser's own words, and the exception is not one uwlab would otherwise let through."""
    bad = tmp_path / "twin.yaml"
    bad.write_text("devices: [")
    err = one_line_error(capsys, ["light", *SUPPLY, "--visa-library", f"{bad}@sim"])
    assert "cannot be loaded (while parsing" in err and str(bad) in err and "Traceback" not in err, err


# (argv, the words of the refusal): a number no camera, lens or light could have is a unit error, refused in one line
ABSURD_NUMBERS = [
    (["grab", "--timeout-s", "1e308"], "policy.timeout_s"),
    (["grab", "--timeout-s", "nan"], "policy.timeout_s"),
    (["sim", "supply", "--seed", "-1"], "seed"),
    (["spectrum", "--instrument", "ocean-insight", "--sim", "--raw", "--area-cm2", "0"], "area-cm2"),
    (["design", str(CONFIGS / "design" / "example.toml"), "--grid", "lens.f_number=1:1e308:1e-308"], "too many"),
    (["design", str(CONFIGS / "design" / "example.toml"), "--grid", "lens.f_number=-1e308:1e308:1"], "too many"),
    (["sim", "charuco", str(DOME), "--medium", "air", "--out", "OUT", "--lens-k1", "1e308"], "--lens-k1"),
    (["sim", "charuco", str(DOME), "--medium", "air", "--out", "OUT", "--lens-k1", "nan"], "--lens-k1"),
]


@pytest.mark.parametrize(("argv", "words"), ABSURD_NUMBERS, ids=[" ".join(a[-2:]) for a, _ in ABSURD_NUMBERS])
def test_an_absurd_number_is_refused_in_one_line(tmp_path, capsys, argv, words):
    err = one_line_error(capsys, [str(tmp_path / "out") if word == "OUT" else word for word in argv])
    assert words in err, err


@pytest.mark.timeout(60)
@pytest.mark.parametrize("inside", [False, True], ids=["file", "in the folder"])
def test_a_fifo_as_a_characterised_sensor_is_refused_for_what_it_is(tmp_path, inside):
    """`uwlab fit --sensor CAMERA=FROM`: a FIFO given as the profile, or as the one TOML of an emva folder, is refused
    as not a regular file (not as a missing profile), never opened."""
    from uwlab.experiments.calibration.forward import characterised_sensor

    fifo = _fifo(tmp_path / "camera.toml")
    with pytest.raises(ConfigError, match=f"{fifo}.*not a regular file"):
        characterised_sensor(str(tmp_path if inside else fifo))
