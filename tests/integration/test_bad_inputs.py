"""The CLI's error contract, table-driven, with every command run as a real process (``python -m uwlab.cli.main``).

Each bad input of issues 10 and 16 exits with code 2 and exactly one line on stderr naming the key or value, with no
traceback anywhere and nothing written (each row writes into its own scratch directory, which must stay empty).
Ctrl-C — at start-up, in `uwlab sim serial` / `uwlab sim camera`, and while a simulated sweep's simulator processes
start (the terminal sends SIGINT to the whole process group) — exits with code 130 and one line ``interrupted``.

Read-only outputs: a directory in which the running user cannot create files. CI runs as root, whom permission bits
do not stop, so as root that is ``/sys/fs`` (sysfs refuses new files to everyone); otherwise a directory with mode
0555. The fixture checks the premise, so that a writable "read-only" directory cannot make the rows pass vacuously.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import tempfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from uwlab.sim.devices.camera import SimTruth
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.emva.simulate import simulate_photon_transfer
from uwlab.model.sensor import load_sensor_profile

from tests.support.cli_process import finish, run, uwlab, wait_until
from tests.support.paths import DATA, EXAMPLE, ROOT
from tests.support.plans import CAMPAIGN_DEFAULTS, write_campaign

SEKONIC = DATA / "sekonic_c7000_synthetic.csv"
DOME = ROOT / "configs" / "design" / "dome-8mm.toml"


def write_sweep_plan(path: Path, **defaults) -> Path:
    """The rows' sweep plan: the small campaign's first sweep with spectra at the target only; ``defaults`` changed."""
    return write_campaign(path, "bad-inputs", sweeps=1, spectrometer=["target"], **defaults)


def assert_one_line(err: str, out: str, *names: str) -> None:
    """One line, `uwlab VERB: error: ...`, and nothing before it (no progress bar: the refusal came first)."""
    assert "Traceback" not in err + out, err
    assert err.startswith("uwlab ") and ": error: " in err, f"not the error line alone: {err!r}"
    assert err.endswith("\n") and err.count("\n") == 1, f"not one line: {err!r}"
    for name in names:
        assert name in err, f"{name!r} not named in {err!r}"


@pytest.fixture(scope="module")
def read_only_dir(tmp_path_factory) -> Path:
    if os.geteuid() == 0:
        directory = Path("/sys/fs")
    else:
        directory = tmp_path_factory.mktemp("read-only")
        directory.chmod(0o555)
    with pytest.raises(OSError):
        with tempfile.TemporaryFile(dir=directory):
            pass
    return directory


@pytest.fixture(scope="module")
def ctx(tmp_path_factory, read_only_dir):
    """Inputs shared by the rows: a simulated sweep's dataset (fit, report), an EMVA photon-transfer dataset, an
    empty dataset, the plan, an existing file."""
    base = tmp_path_factory.mktemp("bad-inputs")
    plan = write_sweep_plan(base / "plan.toml")
    sweep = base / "sweep"
    code, out, err = run("sweep", plan, "--sim", "--out", sweep, "--non-interactive")
    assert code == 0, err
    truth = SimTruth.from_sensor_profile(load_sensor_profile("imx250m"), resolution_px=(32, 32))
    emva = base / "emva"
    simulate_photon_transfer(
        emva,
        truth,
        rate_e_per_s=1.07e5,
        quantum_efficiency=0.6,
        exposures_us=np.linspace(3e3, 120e3, 12),
        frames=2,
        seed=1,
    )
    empty = base / "empty"
    Dataset.create(empty, {"name": "empty"}, plan_sha256="0" * 64, sim=True).close()
    existing = base / "existing.txt"
    existing.write_text("recorded\n")
    sekonic = SEKONIC.read_text().splitlines(keepends=True)
    stray = base / "stray.csv"
    stray.write_text("".join(sekonic) + "Spectral Data 99999[nm],5\n")
    short = base / "short.csv"
    short.write_text(
        "".join(line for line in sekonic if not line.startswith("Spectral Data"))
        + "".join([line for line in sekonic if line.startswith("Spectral Data")][:3])
    )

    def plan_with(**defaults) -> Path:
        assert set(defaults) <= set(CAMPAIGN_DEFAULTS), defaults  # a changed value, not an unknown key
        return write_sweep_plan(base / f"plan-{abs(hash(repr(defaults)))}.toml", **defaults)

    return SimpleNamespace(
        plan=plan,
        sweep=sweep,
        emva=emva,
        empty=empty,
        existing=existing,
        ro=read_only_dir,
        plan_with=plan_with,
        stray=stray,
        short=short,
        base=base,
    )


# (row id, argv from (ctx, scratch dir), what the one line must name)
ROWS = [
    # issue 10
    ("grab --save unwritable", lambda c, s: ["grab", "--save", c.ro / "frames"], ["--save", "cannot write"]),
    ("grab --save missing parent", lambda c, s: ["grab", "--save", s / "no" / "frames"], ["--save", "does not exist"]),
    ("fit on an empty dataset", lambda c, s: ["fit", c.empty, "--out", s / "fit"], ["dataset", "no points"]),
    (
        "demo --out an existing file",
        lambda c, s: ["demo", "--out", c.existing],
        ["--out", "existing.txt", "not a directory"],
    ),
    ("sim camera bad address", lambda c, s: ["sim", "camera", "--gige", "--address", "127.0.0.300"], ["127.0.0.300"]),
    # refused before sampling: the sampling bar (drawn on stderr at the first step) would precede the line
    (
        "fit --train misspelled",
        lambda c, s: ["fit", c.sweep, "--train", "imx250-30mm-f3", "--out", s / "fit"],
        ["--train", "imx250-30mm-f3"],
    ),
    (
        "fit --held-out misspelled",
        lambda c, s: ["fit", c.sweep, "--held-out", "three", "--out", s / "fit"],
        ["--held-out", "three", "loo"],
    ),
    (
        "fit --dask not an address",
        lambda c, s: ["fit", c.sweep, "--dask", "scheduler:8786", "--out", s / "fit"],
        ["--dask", "scheduler:8786", "tcp://"],
    ),
    (
        "report --out in a missing directory",
        lambda c, s: ["report", c.sweep, "--out", s / "nonexistent" / "r.html"],
        ["--out", "does not exist"],
    ),
    ("design on a directory", lambda c, s: ["design", ROOT / "configs"], [str(ROOT / "configs")]),
    (
        "design focal length in m",
        lambda c, s: ["design", EXAMPLE, "--set", "lens.focal_length_mm=0.03"],
        ["lens.focal_length_mm", "0.03"],
    ),
    (
        "design altitude 1e308",
        lambda c, s: ["design", EXAMPLE, "--set", "operation.altitude_m=1e308"],
        ["operation.altitude_m"],
    ),
    ("design infinite grid", lambda c, s: ["design", EXAMPLE, "--grid", "lens.f_number=0:inf:1"], ["lens.f_number"]),
    (
        "design grid too large to print",
        lambda c, s: [
            "design",
            EXAMPLE,
            "--grid",
            "operation.altitude_m=0.1:100:0.01",
            "--grid",
            "lens.f_number=2,4",
            "--json",
        ],
        ["--out"],
    ),
    (
        "design --plot unwritable",
        lambda c, s: ["design", EXAMPLE, "--plot", c.ro / "plots"],
        ["--plot", "cannot write"],
    ),
    (
        "design --plot missing parent",
        lambda c, s: ["design", EXAMPLE, "--plot", s / "no" / "plots"],
        ["--plot", "does not exist"],
    ),
    (
        "emva wavelength in µm",
        lambda c, s: ["emva", "characterize", c.emva, "--wavelength-nm", "0.55"],
        ["--wavelength-nm", "0.55"],
    ),
    (
        "emva pixel size in nm",
        lambda c, s: ["emva", "characterize", c.emva, "--pixel-size-um", "3450"],
        ["--pixel-size-um", "3450"],
    ),
    # issue 16
    (
        "sweep --out 300-byte name",
        lambda c, s: ["sweep", c.plan, "--sim", "--out", s / ("a" * 300)],
        ["--out", "300-byte"],
    ),
    (
        "sweep --out not UTF-8",
        lambda c, s: ["sweep", c.plan, "--sim", "--out", os.fsencode(s) + b"/caf\xe9"],
        ["--out", "UTF-8"],
    ),
    ("sweep --out read-only", lambda c, s: ["sweep", c.plan, "--sim", "--out", c.ro / "dataset"], ["--out"]),
    ("sweep --resume read-only", lambda c, s: ["sweep", c.plan, "--sim", "--resume", c.ro], ["--resume"]),
    (
        "frames_per_point 200000",
        lambda c, s: ["sweep", c.plan_with(frames_per_point=200000), "--sim", "--out", s / "d"],
        ["frames_per_point", "200000"],
    ),
    (
        "dark_frames 999999",
        lambda c, s: ["sweep", c.plan_with(dark_frames=999999), "--sim", "--out", s / "d"],
        ["dark_frames", "999999"],
    ),
    (
        "range to inf",
        lambda c, s: [
            "sweep",
            c.plan_with(values={**CAMPAIGN_DEFAULTS["values"], "stop": math.inf}),
            "--sim",
            "--out",
            s / "d",
        ],
        ["stop", "inf"],
    ),
    (
        "design --out read-only",
        lambda c, s: ["design", EXAMPLE, "--out", c.ro / "design.parquet"],
        ["--out", "cannot write"],
    ),
    (
        "design grid --out read-only",
        lambda c, s: ["design", EXAMPLE, "--grid", "lens.f_number=2,4", "--out", c.ro / "grid.csv"],
        ["--out", "cannot write"],
    ),
    (
        "design grid larger than the disk",  # ~1.8e12 points: refused after its first chunk, the staging removed
        lambda c, s: [
            "design",
            EXAMPLE,
            "--grid",
            "operation.altitude_m=0.5:5:0.000001",
            "--grid",
            "lens.f_number=1:20:0.001",
            "--grid",
            "sensor.gain_db=0:20:1",
            "--out",
            s / "huge.parquet",
        ],
        ["--out", "GiB free"],
    ),
    ("Sekonic stray 99999 nm row", lambda c, s: ["spectrum", "--import", c.stray], ["99999", "line"]),
    ("Sekonic 3-sample file", lambda c, s: ["spectrum", "--import", c.short], ["short.csv", "line"]),
    ("dataset check on a non-dataset", lambda c, s: ["dataset", "check", c.base], ["not a dataset"]),
    (
        "emva characterize --out read-only",
        lambda c, s: ["emva", "characterize", c.emva, "--out", c.ro / "emva"],
        ["--out", "cannot write"],
    ),
    (
        "emva export --out read-only",
        lambda c, s: ["emva", "export", c.emva, "--out", c.ro / "descriptor"],
        ["--out", "cannot write"],
    ),
    ("fit --out read-only", lambda c, s: ["fit", c.sweep, "--out", c.ro / "fit"], ["--out", "cannot write"]),
    ("report --out read-only", lambda c, s: ["report", c.sweep, "--out", c.ro / "r.html"], ["--out", "cannot write"]),
    ("demo --out read-only", lambda c, s: ["demo", "--out", c.ro / "demo"], ["--out", "cannot write"]),
    (
        "spectrum --out read-only",
        lambda c, s: ["spectrum", "--import", SEKONIC, "--out", c.ro / "s.csv"],
        ["--out", "cannot write"],
    ),
    (
        "port board --out read-only",
        lambda c, s: ["port", "board", "--out", c.ro / "board.png"],
        ["--out", "cannot write"],
    ),
    (
        "port trace --plot read-only",
        lambda c, s: ["port", "trace", EXAMPLE, "--plot", c.ro / "plots"],
        ["--plot", "cannot write"],
    ),
    (
        "sim charuco --out read-only",
        lambda c, s: ["sim", "charuco", DOME, "--medium", "air", "--poses", "1", "--out", c.ro / "images"],
        ["--out", "cannot write"],
    ),
    (
        "light calibrate --out read-only",
        lambda c, s: [
            "light",
            "calibrate",
            "--light",
            s / "no-port",
            "--spectrometer",
            s / "no-port",
            "--out",
            c.ro / "calibration.csv",
        ],
        ["--out", "cannot write"],
    ),
]


@pytest.mark.parametrize("argv, names", [pytest.param(a, n, id=i) for i, a, n in ROWS])
def test_bad_input_is_one_line_and_exit_2(ctx, tmp_path, argv, names):
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    before = ctx.existing.read_text()
    code, out, err = run(*argv(ctx, scratch))
    assert code == 2, err
    assert_one_line(err, out, *names)
    assert list(scratch.iterdir()) == [], "written before refusing"
    assert ctx.existing.read_text() == before


def test_a_second_gige_server_on_the_same_address_is_refused():
    address = f"127.0.{os.getpid() % 200 + 1}.251"
    first = uwlab("sim", "camera", "--gige", "--json", "--address", address)
    try:
        assert address in first.stdout.readline()
        code, out, err = run("sim", "camera", "--gige", "--address", address)
        assert code == 2
        assert_one_line(err, out, address, "in use", f"process {first.pid}")
        assert first.poll() is None, "the first server must keep serving"
    finally:
        first.send_signal(signal.SIGTERM)
        assert finish(first)[0] == 0


def _children(pid: int) -> list[tuple[int, str]]:
    """(pid, command line) of the processes whose parent is `pid`."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            if ppid == pid:
                found.append((int(entry.name), (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()))
        except (OSError, IndexError, ValueError):
            continue
    return found


def assert_interrupted(process: subprocess.Popen, verb: str) -> None:
    code, out, err = finish(process)
    assert code == 130, err
    assert "Traceback" not in out + err, err
    assert err == f"uwlab {verb}: interrupted\n"


def test_ctrl_c_at_start_up():
    """SIGINT while the chosen subcommand's modules are still being imported (numpy just mapped)."""
    process = uwlab("sim", "serial", "--json")

    def importing() -> bool:
        return "_multiarray_umath" in Path(f"/proc/{process.pid}/maps").read_text()

    wait_until(importing, process, "numpy is being imported", every_s=0.005)
    process.send_signal(signal.SIGINT)
    assert_interrupted(process, "sim")


def test_ctrl_c_stops_sim_serial_and_removes_its_ports():
    process = uwlab("sim", "serial", "--json")
    ports = process.stdout.readline()
    assert '"light"' in ports
    os.killpg(process.pid, signal.SIGINT)  # as a terminal does: the simulator processes get it too
    assert_interrupted(process, "sim")
    assert not any(os.path.lexists(p) for p in (ports.split('"')[3], ports.split('"')[7]))


def test_ctrl_c_stops_sim_camera():
    process = uwlab("sim", "camera", "--gige", "--json", "--address", f"127.0.{os.getpid() % 200 + 1}.250")
    assert '"address"' in process.stdout.readline()
    os.killpg(process.pid, signal.SIGINT)
    assert_interrupted(process, "sim")


def test_ctrl_c_stops_explore():
    process = uwlab("explore", "--no-browser", "--json", "--port", "0")
    assert '"url"' in process.stdout.readline()
    os.killpg(process.pid, signal.SIGINT)
    assert_interrupted(process, "explore")


def test_ctrl_c_while_the_sweeps_simulator_processes_start(tmp_path):
    """The terminal's SIGINT reaches the sweep while its simulator processes still import (they are in process
    groups of their own; the sweep stops them): no traceback from any of them, one line from the sweep."""
    plan = write_sweep_plan(tmp_path / "plan.toml")
    process = uwlab("sweep", plan, "--sim", "--out", tmp_path / "d")

    def simulator_starting() -> bool:
        return any("uwlab.sim.devices.serial_sim" in cmdline for _, cmdline in _children(process.pid))

    wait_until(simulator_starting, process, "a simulator process was started", every_s=0.005)
    os.killpg(process.pid, signal.SIGINT)
    assert_interrupted(process, "sweep")
