"""Issue 36's input audit: every file-taking option and positional of every ``uwlab`` verb fed what a careless user or
an attacker would give it, and every numeric option fed absurd values.

A file input gets a FIFO (opening it for reading blocks), ``/dev/zero`` (reads for ever), a directory and an
over-size sparse file (2 GB); a folder input gets a FIFO, a ``/dev/zero`` link and a directory where the command
looks for its files. Every float option gets 1e-308, 1e308, nan, inf, -1 and 0; every int option -1, 0 and 1e20.
Each run is a child process (forked from a parent that has imported the CLI once, so a run costs no start-up) killed
after 10 s: a run still going then is a hang (for the servers — ``sim``, ``explore`` — of a numeric value, one that
was accepted and serves). A run is refused in one line when it exits 2 with one line on stderr and no traceback.

Target (issue 36): every non-regular or over-size input refused in one line within 2 s; 0 tracebacks, 0 hangs.

Usage: python benchmarks/input_audit.py [--details]   (prints JSON; the details list every run)
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from uwlab.cli.main import SUBCOMMANDS, build_parser, main  # noqa: E402

TIMEOUT_S = 10.0
TARGET_S = 2.0
CONFIGS = ROOT / "configs"
DATA = ROOT / "tests" / "data"
DESIGN = CONFIGS / "design" / "example.toml"
DOME = CONFIGS / "design" / "dome-8mm.toml"
SIM_TANK = CONFIGS / "rigs" / "sim-tank.toml"
LAMP = DATA / "ocean_insight_lamp_3100k.LMP"
SUPPLY_YAML = CONFIGS / "instruments" / "sim" / "scpi-dc-supply.yaml"
SUPPLY = ["--instrument", "scpi-dc-supply", "--resource", "TCPIP0::192.168.0.10::inst0::INSTR"]
SIM_SUPPLY = [*SUPPLY, "--visa-library", f"{SUPPLY_YAML}@sim"]
SIM_SPECTRUM = ["spectrum", "--instrument", "ocean-insight", "--sim"]
CALIBRATE = ["spectrometer", "calibrate", "--out-csv", "calibration.csv"]  # in the run's own folder
LONG_RUNNING = ("sim", "explore", "demo")  # servers, and the demo's campaign: accepted, they run past the timeout


def run(argv: list[str], cwd: Path, command: Callable[[list[str]], int] = main) -> dict:
    """``uwlab ARGV`` (or ``command(argv)``) in a forked child, killed after `TIMEOUT_S`: exit code (None: killed),
    stderr, time."""
    err_path, out_path = cwd / "stderr.txt", cwd / "stdout.txt"
    start = time.monotonic()
    pid = os.fork()
    if pid == 0:  # the child: the command, its output to files, nothing back into the parent
        code = 1
        try:
            os.setsid()
            os.chdir(cwd)
            out = os.open(out_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
            err = os.open(err_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
            os.dup2(out, 1)
            os.dup2(err, 2)
            sys.stdin = open(os.devnull)
            code = command(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        except BaseException:
            import traceback

            traceback.print_exc()
            code = 1
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    rc = None
    while time.monotonic() - start < TIMEOUT_S:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            rc = os.waitstatus_to_exitcode(status)
            break
        time.sleep(0.01)
    elapsed = time.monotonic() - start
    if rc is None:
        os.killpg(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    stderr = err_path.read_text(errors="replace") if err_path.exists() else ""
    stdout = out_path.read_text(errors="replace")[-2000:] if out_path.exists() else ""
    return {
        "rc": rc,
        "stderr_lines": stderr.count("\n"),
        "traceback": "Traceback" in stderr,
        "time_s": round(elapsed, 3),
        "message": stderr.strip().splitlines()[-1][:300] if stderr.strip() else "",
        "stdout": stdout,
    }


# --- bad inputs --------------------------------------------------------------------------------------------------


def fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def device(path: Path) -> Path:
    """/dev/zero itself where a path is given, a link to it where a file inside a folder is looked for."""
    path.symlink_to("/dev/zero")
    return path


def directory(path: Path) -> Path:
    path.mkdir()
    return path


def oversize(path: Path) -> Path:
    with open(path, "wb") as fh:
        fh.truncate(2_000_000_001)
    return path


BAD = {"fifo": fifo, "/dev/zero": device, "directory": directory, "over-size 2 GB": oversize}


# --- the file inputs: (name, file name, argv(F, tmp)) --------------------------------------------------------------

FileCase = tuple[str, str, Callable[[Path, Path], list[str]]]

FILE_CASES: list[FileCase] = [
    ("design CONFIG", "d.toml", lambda f, t: ["design", str(f)]),
    ("design solve CONFIG", "d.toml", lambda f, t: ["design", "solve", str(f), "--free", "lens.f_number=2:8"]),
    ("design --set sensor.profile", "s.toml", lambda f, t: ["design", str(DESIGN), "--set", f"sensor.profile={f}"]),
    ("design --set light.spectrum", "s.csv", lambda f, t: ["design", str(DESIGN), "--set", f"light.spectrum={f}"]),
    ("design --set water.type", "w.csv", lambda f, t: ["design", str(DESIGN), "--set", f"water.type={f}"]),
    ("explore CONFIG", "d.toml", lambda f, t: ["explore", str(f), "--no-browser", "--port", "0", "--json"]),
    ("explore --profile", "p.toml", lambda f, t: ["explore", "--profile", str(f), "--no-browser", "--port", "0"]),
    ("devices --config", "r.toml", lambda f, t: ["devices", "--config", str(f)]),
    ("devices --cti", "p.cti", lambda f, t: ["devices", "--cti", str(f)]),
    ("grab --config", "r.toml", lambda f, t: ["grab", "--config", str(f)]),
    ("grab --cti", "p.cti", lambda f, t: ["grab", "--backend", "harvesters", "--cti", str(f)]),
    ("grab --sensor", "s.toml", lambda f, t: ["grab", "--sensor", str(f)]),
    ("light --rig", "rig.toml", lambda f, t: ["light", *SIM_SUPPLY, "--rig", str(f)]),
    ("light --instrument FILE", "i.toml", lambda f, t: ["light", "--instrument", str(f), "--resource", "ASRL1::INSTR"]),
    ("light --visa-library FILE@sim", "v.yaml", lambda f, t: ["light", *SUPPLY, "--visa-library", f"{f}@sim"]),
    (
        "light calibrate --calibration",
        "c.csv",
        lambda f, t: [
            "light", "calibrate", "--light", "/dev/null", "--spectrometer-instrument", "ocean-insight",
            "--calibration", str(f), "--out", str(t / "o.csv"),
        ],
    ),
    (
        "light calibrate --dark",
        "d.csv",
        lambda f, t: [
            "light", "calibrate", "--light", "/dev/null", "--spectrometer-instrument", "ocean-insight",
            "--dark", str(f), "--out", str(t / "o.csv"),
        ],
    ),
    (
        "light calibrate --instrument FILE",
        "i.toml",
        lambda f, t: [
            "light", "calibrate", "--instrument", str(f), "--resource", "ASRL1::INSTR",
            "--spectrometer", "/dev/null", "--out", str(t / "o.csv"),
        ],
    ),
    (
        "light calibrate --visa-library FILE@sim",
        "v.yaml",
        lambda f, t: [
            "light", "calibrate", *SUPPLY, "--visa-library", f"{f}@sim",
            "--spectrometer", "/dev/null", "--out", str(t / "o.csv"),
        ],
    ),
    ("spectrum --import", "s.csv", lambda f, t: ["spectrum", "--import", str(f)]),
    ("spectrum --calibration", "c.cal", lambda f, t: [*SIM_SPECTRUM, "--calibration", str(f)]),
    ("spectrum --dark", "d.csv", lambda f, t: [*SIM_SPECTRUM, "--dark", str(f)]),
    ("spectrum --sim-lamp", "l.LMP", lambda f, t: [*SIM_SPECTRUM, "--raw", "--sim-lamp", str(f)]),
    ("spectrum --instrument FILE", "i.toml", lambda f, t: ["spectrum", "--instrument", str(f)]),
    ("spectrometer calibrate --lamp", "l.LMP", lambda f, t: [*CALIBRATE, "--sim", "--lamp", str(f)]),
    (
        "spectrometer calibrate --sim-lamp",
        "l.LMP",
        lambda f, t: [*CALIBRATE, "--sim", "--lamp", str(LAMP), "--sim-lamp", str(f)],
    ),
    (
        "spectrometer calibrate --lamp-spectrum",
        "s.txt",
        lambda f, t: [
            *CALIBRATE, "--lamp", str(LAMP), "--lamp-spectrum", str(f),
            "--dark-spectrum", str(DATA / "spectrasuite_dark_FLMS01234.txt"),
        ],
    ),
    (
        "spectrometer calibrate --dark-spectrum",
        "d.txt",
        lambda f, t: [
            *CALIBRATE, "--lamp", str(LAMP), "--lamp-spectrum",
            str(DATA / "oceanview_lamp_FLMS01234.txt"), "--dark-spectrum", str(f),
        ],
    ),
    ("sim serial --config", "r.toml", lambda f, t: ["sim", "serial", "--config", str(f)]),
    ("sim camera --config", "r.toml", lambda f, t: ["sim", "camera", "--gige", "--config", str(f)]),
    ("sim camera --rig-state", "state.json", lambda f, t: ["sim", "camera", "--gige", "--rig-state", str(f)]),
    ("sim charuco CONFIG", "d.toml", lambda f, t: ["sim", "charuco", str(f), "--medium", "air", "--out", str(t / "o")]),
    (
        "sim charuco --board",
        "b.toml",
        lambda f, t: ["sim", "charuco", str(DOME), "--medium", "air", "--out", str(t / "o"), "--board", str(f)],
    ),
    ("sweep PLAN", "p.toml", lambda f, t: ["sweep", str(f), "--sim", "--out", str(t / "ds")]),
    ("emva characterize --descriptor", "e.txt", lambda f, t: ["emva", "characterize", "--descriptor", str(f)]),
    ("fit --config", "f.toml", lambda f, t: ["fit", str(t / "base" / "ds"), "--config", str(f), "--out", str(t / "o")]),
    ("fit --sensor FILE", "s.toml", lambda f, t: ["fit", str(t / "base" / "ds"), "--sensor", str(f)]),
    ("report --out", "r.html", lambda f, t: ["report", str(t / "base"), "--out", str(f)]),
    ("port trace CONFIG", "d.toml", lambda f, t: ["port", "trace", str(f)]),
    ("port board --board", "b.toml", lambda f, t: ["port", "board", "--board", str(f), "--out", str(t / "b.png")]),
    (
        "port calibrate --config",
        "d.toml",
        lambda f, t: ["port", "calibrate", str(t / "base"), str(t / "base"), "--port", "flat", "--config", str(f)],
    ),
    (
        "port calibrate --board",
        "b.toml",
        lambda f, t: [
            "port", "calibrate", str(t / "base"), str(t / "base"), "--port", "flat", "--config", str(DOME),
            "--board", str(f),
        ],
    ),
    ("mtf IMAGE", "i.tif", lambda f, t: ["mtf", str(f)]),
    ("mtf IMAGE (png)", "i.png", lambda f, t: ["mtf", str(f)]),
]  # fmt: skip

# --- the folder inputs: (name, what must happen, folder kind, the entry made bad in it, argv(D, tmp)) --------------
# D is a copy of a small simulated dataset (`base/ds`; "dataset-in": inside D) or a folder holding just the bad entry
# ("fit": and an empty samples.parquet beside it). What must happen, besides ending in one line within the timeout:
#   named     refused, the line naming the entry
#   reported  exit 0 or 1 with the entry (or the word "damaged") on stdout: `dataset check`/`show` name a damaged
#             copy and read the other one
#   tolerated refused naming the entry, or done without it: a dataset read from its other copy, an over-size lock
#             (no holder record) taken over
#   skipped   the command looks for regular files only: the entry is passed over (refused or done for another reason)
#   served    a server: it starts, reading nothing from the folder until asked (the explorer's own boundary)

FolderCase = tuple[str, str, str, str, Callable[[Path, Path], list[str]]]

FOLDER_CASES: list[FolderCase] = [
    ("dataset show DIR: manifest.json", "reported", "dataset", "manifest.json",
     lambda d, t: ["dataset", "show", str(d)]),
    ("dataset show DIR: metadata.json", "reported", "dataset", "metadata.json",
     lambda d, t: ["dataset", "show", str(d)]),
    ("dataset check DIR: manifest.json", "reported", "dataset", "manifest.json",
     lambda d, t: ["dataset", "check", str(d)]),
    ("dataset check DIR: backup", "reported", "dataset", "manifest.backup.json",
     lambda d, t: ["dataset", "check", str(d)]),
    ("dataset check DIR: a part", "reported", "dataset", "parts/PART", lambda d, t: ["dataset", "check", str(d)]),
    ("dataset check --repair DIR: lock", "tolerated", "dataset", "lock",
     lambda d, t: ["dataset", "check", "--repair", str(d)]),
    ("sweep --resume DIR: manifest", "tolerated", "dataset", "manifest.json",
     lambda d, t: ["sweep", str(t / "base" / "plan.toml"), "--sim", "--resume", str(d)]),
    ("sweep --resume DIR: lock", "tolerated", "dataset", "lock",
     lambda d, t: ["sweep", str(t / "base" / "plan.toml"), "--sim", "--resume", str(d)]),
    ("emva characterize DIR: a part", "named", "dataset", "parts/PART",
     lambda d, t: ["emva", "characterize", str(d), "--irradiance", "1", "--wavelength-nm", "550"]),
    ("emva export DIR: metadata", "tolerated", "dataset", "metadata.json",
     lambda d, t: ["emva", "export", str(d), "--irradiance", "1", "--wavelength-nm", "550", "--out", str(t / "o")]),
    ("emva fleet DIR: a descriptor", "skipped", "empty", "EMVA1288x.txt", lambda d, t: ["emva", "fleet", str(d)]),
    ("fit DATASET: a part", "named", "dataset", "parts/PART", lambda d, t: ["fit", str(d), "--out", str(t / "o")]),
    ("fit --sensor CAMERA=DIR: profile", "skipped", "empty", "sensor.toml",
     lambda d, t: ["fit", str(t / "base" / "ds"), "--sensor", f"imx250m={d}"]),
    ("report DIR: summary.json", "named", "fit", "fit/summary.json", lambda d, t: ["report", str(d)]),
    ("report DIR: emva.json", "named", "empty", "emva/emva.json", lambda d, t: ["report", str(d)]),
    ("report DIR: a dataset's manifest", "tolerated", "dataset-in", "ds/manifest.json",
     lambda d, t: ["report", str(d)]),
    ("design --posterior DIR: samples", "named", "empty", "samples.parquet",
     lambda d, t: ["design", str(DESIGN), "--posterior", str(d)]),
    ("explore --data-dir DIR", "served", "empty", "water.csv",
     lambda d, t: ["explore", "--data-dir", str(d), "--no-browser", "--port", "0", "--json"]),
    ("port calibrate DIR DIR: an image", "named", "empty", "view.png",
     lambda d, t: ["port", "calibrate", str(d), str(d), "--port", "flat", "--config", str(DOME)]),
    ("devices --cti DIR: a producer", "skipped", "empty", "p.cti", lambda d, t: ["devices", "--cti", str(d)]),
]  # fmt: skip


# --- numeric options: every float/int option of every verb, on a command line otherwise valid ----------------------

FLOATS = ["1e-308", "1e308", "nan", "inf", "-1", "0"]
INTS = ["-1", "0", "100000000000000000000"]


def numeric_bases(tmp: Path) -> dict[tuple[str, str], list[str]]:
    """(verb, option) → a command line the option is added to, run in the fresh folder ``tmp``."""
    ds = str(tmp / "base" / "ds")
    out = str(tmp / "o")
    sim_spec = [*SIM_SPECTRUM, "--raw"]
    cal = [*CALIBRATE, "--sim", "--lamp", str(LAMP)]
    light_cal = ["light", "calibrate", "--light", "/dev/null", "--spectrometer-instrument", "ocean-insight", "--out",
                 f"{out}.csv"]  # fmt: skip
    supply = ["light", *SIM_SUPPLY]
    return {
        ("design", "--confidence"): ["design", str(DESIGN), "--posterior", ds],
        ("explore", "--port"): ["explore", "--no-browser", "--json"],
        ("grab", "--exposure-us"): ["grab", "--frames", "1"],
        ("grab", "--gain-db"): ["grab", "--frames", "1"],
        ("grab", "--frames"): ["grab"],
        ("grab", "--timeout-s"): ["grab", "--frames", "1"],
        ("light", "--level"): supply,
        ("light", "--max-current-a"): supply,
        ("light", "--forward-voltage-v"): supply,
        ("light calibrate", "--max-current-a"): [
            "light",
            "calibrate",
            *SUPPLY,
            "--spectrometer",
            "/dev/null",
            "--out",
            f"{out}.csv",
        ],  # fmt: skip
        ("light calibrate", "--forward-voltage-v"): [
            "light",
            "calibrate",
            *SUPPLY,
            "--spectrometer",
            "/dev/null",
            "--out",
            f"{out}.csv",
        ],  # fmt: skip
        ("light calibrate", "--area-cm2"): light_cal,
        ("light calibrate", "--integration-ms"): light_cal,
        ("light calibrate", "--levels"): light_cal,
        ("spectrum", "--area-cm2"): sim_spec,
        ("spectrum", "--integration-ms"): sim_spec,
        ("spectrum", "--average"): sim_spec,
        ("spectrometer calibrate", "--area-cm2"): cal,
        ("spectrometer calibrate", "--integration-ms"): cal,
        ("spectrometer calibrate", "--average"): cal,
        ("sim camera", "--seed"): ["sim", "camera", "--gige", "--json"],
        ("sim camera", "--incomplete-every"): ["sim", "camera", "--gige", "--json"],
        ("sim charuco", "--poses"): ["sim", "charuco", str(DOME), "--medium", "air", "--out", out],
        ("sim charuco", "--seed"): ["sim", "charuco", str(DOME), "--medium", "air", "--out", out, "--poses", "1"],
        ("sim charuco", "--downsample"): ["sim", "charuco", str(DOME), "--medium", "air", "--out", out, "--poses", "1"],
        ("sim charuco", "--lens-k1"): ["sim", "charuco", str(DOME), "--medium", "air", "--out", out, "--poses", "1"],
        ("sim supply", "--tcp"): ["sim", "supply"],
        ("sim supply", "--seed"): ["sim", "supply"],
        ("emva characterize", "--wavelength-nm"): ["emva", "characterize", ds, "--irradiance", "1"],
        ("emva characterize", "--pixel-size-um"): [
            "emva",
            "characterize",
            ds,
            "--irradiance",
            "1",
            "--wavelength-nm",
            "550",
        ],  # fmt: skip
        ("emva fleet", "--pixel-size-um"): ["emva", "fleet", str(tmp / "base")],
        ("emva export", "--wavelength-nm"): ["emva", "export", ds, "--irradiance", "1", "--out", out],
        ("emva export", "--pixel-size-um"): [
            "emva",
            "export",
            ds,
            "--irradiance",
            "1",
            "--wavelength-nm",
            "550",
            "--out",
            out,
        ],  # fmt: skip
        ("demo", "--seed"): ["demo", "--out", out],
        ("port calibrate", "--max-distortion-px"): [
            "port",
            "calibrate",
            str(tmp / "base"),
            str(tmp / "base"),
            "--port",
            "dome",
            "--config",
            str(DOME),
        ],  # fmt: skip
        ("port board", "--dpi"): ["port", "board", "--out", f"{out}.png"],
    }


def numeric_options() -> list[tuple[str, str, str]]:
    """(verb, option, 'float'|'int') of every option parsed as a number, walked from the parsers."""
    found = []

    def walk(parser: argparse.ArgumentParser, path: list[str]) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, [*path, name])
            elif action.type in (float, int) and action.option_strings:
                found.append((" ".join(path), action.option_strings[-1], action.type.__name__))

    for verb in SUBCOMMANDS:
        for action in build_parser(verb)._actions:
            if isinstance(action, argparse._SubParsersAction):
                walk(action.choices[verb], [verb])
    return found


def design_keys() -> list[str]:
    """Every numeric key of the example design, SECTION.KEY."""
    from uwlab.model.data import read_toml

    keys = []
    for section, table in read_toml(DESIGN).items():
        if isinstance(table, dict):
            keys += [
                f"{section}.{k}" for k, v in table.items() if isinstance(v, int | float) and not isinstance(v, bool)
            ]
    return keys


# --- the campaign ------------------------------------------------------------------------------------------------


def prepare(tmp: Path) -> None:
    """A small simulated dataset (`base/ds`) from a one-sweep plan (`base/plan.toml`), made once."""
    from tests.support.plans import write_campaign

    base = tmp / "base"
    base.mkdir()
    write_campaign(base / "plan.toml", "audit", sweeps=1)
    result = run(["sweep", str(base / "plan.toml"), "--sim", "--out", str(base / "ds")], base)
    if result["rc"] != 0:
        raise SystemExit(f"the base dataset could not be made: {result}")


def folder_for(kind: str, entry: str, tmp: Path, make: Callable[[Path], Path]) -> tuple[Path, Path]:
    """The folder given to the command, and the bad entry made in it."""
    import shutil

    folder = tmp / "in"
    if kind in ("dataset", "dataset-in"):
        target = folder / "ds" if kind == "dataset-in" else folder
        shutil.copytree(tmp / "base" / "ds", target, symlinks=True)
        (target / "lock").unlink(missing_ok=True)
    else:
        folder.mkdir()
    if kind == "fit":
        (folder / "fit").mkdir()
        (folder / "fit" / "samples.parquet").write_bytes(b"")
    if "PART" in entry:
        part = next(p for p in sorted((folder / "parts").iterdir()) if p.is_file())
        entry = str(part.relative_to(folder))
    path = folder / entry
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists() or path.is_symlink():
        path.unlink() if not path.is_dir() else shutil.rmtree(path)
    make(path)
    return folder, path


def verdict(result: dict, server: bool = False, named: str = "") -> str:
    """How a run ended; a refusal of a bad input counts only when its line names the input (``named``): one that
    names something else was refused before the input was looked at (the probe's command line is wrong)."""
    if result["traceback"]:
        return "traceback"
    if result["rc"] is None:
        return "running" if server else "hang"
    if result["rc"] == 2 and result["stderr_lines"] == 1:
        return "refused in one line" if named in result["message"] else "refused for another reason"
    return "accepted" if result["rc"] == 0 else "other"


def expected(case: str, bad: str) -> str:
    """What a bad file input must do: be refused naming it, but for a folder where a folder is a valid value (a
    GenTL producer folder, whose regular *.cti files are used)."""
    return "skipped" if bad == "directory" and case.endswith("--cti") else "named"


def handled(expect: str, verdict: str, result: dict, name: str) -> bool:
    """Whether a bad input was handled as it must be (`FOLDER_CASES`' comment); a file input must be ``named``."""
    if verdict in ("traceback", "hang", "other") and expect != "reported":
        return False
    return {
        "named": verdict == "refused in one line",
        "reported": result["rc"] in (0, 1) and (name in result["stdout"] or "damaged" in result["stdout"]),
        "tolerated": verdict in ("refused in one line", "accepted"),
        "skipped": verdict in ("refused in one line", "refused for another reason", "accepted"),
        "served": verdict == "running",
    }[expect]


GROUPS = ("file", "folder", "numeric", "design --set", "explorer")


def campaign(groups: tuple[str, ...] = GROUPS) -> dict:
    import shutil

    numeric = numeric_options()  # imports every verb's module here, once: a run's time is the command's own
    warm()
    runs = []
    with tempfile.TemporaryDirectory(prefix="uwlab-input-audit-") as name:
        tmp = Path(name)
        prepare(tmp)

        def fresh() -> Path:
            work = tmp / "w"
            if work.exists():
                shutil.rmtree(work)
            work.mkdir()
            (work / "base").symlink_to(tmp / "base")
            return work

        for case, filename, argv in FILE_CASES if "file" in groups else ():
            for bad, make in BAD.items():
                work = fresh()
                path = Path("/dev/zero") if bad == "/dev/zero" else make(work / filename)
                result = run(argv(path, work), work)
                named = verdict(result, named=path.name)
                runs.append(
                    {"group": "file", "input": case, "bad": bad, **result, "verdict": named,
                     "handled": handled(expected(case, bad), named, result, path.name)}
                )  # fmt: skip
        for case, expect, kind, entry, argv in FOLDER_CASES if "folder" in groups else ():
            for bad, make in BAD.items():
                work = fresh()
                folder, path = folder_for(kind, entry, work, make)
                result = run(argv(folder, work), work)
                named = verdict(result, server=expect == "served", named=path.name)
                runs.append(
                    {"group": "folder", "input": case, "bad": bad, "expect": expect, **result, "verdict": named,
                     "handled": handled(expect, named, result, path.name)}
                )  # fmt: skip
        for verb, option, kind in numeric if "numeric" in groups else ():
            if (verb, option) not in numeric_bases(tmp):
                runs.append({"group": "numeric", "input": f"{verb} {option}", "bad": "", "verdict": "no base line"})
                continue
            for value in FLOATS if kind == "float" else INTS:
                work = fresh()
                result = run([*numeric_bases(work)[verb, option], f"{option}={value}"], work)
                server = verb.split()[0] in LONG_RUNNING
                runs.append(
                    {"group": "numeric", "input": f"{verb} {option}", "bad": value, **result,
                     "verdict": verdict(result, server)}
                )  # fmt: skip
        for key in design_keys() if "design --set" in groups else ():
            for value in FLOATS:
                work = fresh()
                result = run(["design", str(DESIGN), "--set", f"{key}={value}"], work)
                runs.append({"group": "design --set", "input": key, "bad": value, **result, "verdict": verdict(result)})
        for endpoint, key, bad in EXPLORER_CASES if "explorer" in groups else ():
            work = fresh()
            result = run([endpoint, key, bad], work, explorer_request)
            named = "refused" if result["rc"] == 0 and result["stdout"].startswith("4") else "not refused"
            runs.append({"group": "explorer", "input": f"{endpoint} {key}", "bad": bad, **result, "verdict": named})
    return summarise(runs)


# --- the explorer's file-valued keys: a bad file inside its --data-dir, through each endpoint that takes one -------

EXPLORER_CASES = [
    (endpoint, key, bad)
    for endpoint, key in (
        ("/api/design", "water.type"),
        ("/api/design", "light.spectrum"),
        ("/api/design", "sensor.profile"),
        ("/api/sweep", "water.type"),
        ("/api/profile", "path"),
    )
    for bad in BAD
]


def explorer_request(argv: list[str]) -> int:
    """POST the bad file ``argv[2]`` made in a --data-dir as ``argv[1]`` to the endpoint ``argv[0]`` of an explorer
    served in process (Starlette's TestClient); prints the status and the answer (a 4xx is a refusal)."""
    import warnings

    from starlette.testclient import TestClient

    from uwlab.explore.app import create_app
    from uwlab.explore.catalog import Catalog
    from uwlab.explore.inputs import load_served

    endpoint, key, bad = argv
    folder = directory(Path.cwd() / "data")
    name = "profile.toml" if key in ("sensor.profile", "path") else "table.csv"
    path = Path("/dev/zero") if bad == "/dev/zero" else BAD[bad](folder / name)
    if bad == "/dev/zero":
        path = device(folder / name)
    if endpoint == "/api/profile":
        body: dict = {"path": str(path)}
    elif endpoint == "/api/sweep":
        body = {"grid": {key: [str(path)]}, "output": "snr_db"}
    else:
        body = {"text": {key: str(path)}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        served = load_served(DESIGN).with_roots(folder)
        with TestClient(create_app(served, Catalog()), base_url="http://127.0.0.1") as client:
            answer = client.post(endpoint, json=body)
    print(answer.status_code, answer.text[:300])
    return 0


def summarise(runs: list[dict]) -> dict:
    inputs = [r for r in runs if r["group"] in ("file", "folder")]
    timed = [r for r in inputs if r["handled"] and r["verdict"] != "running"]
    numeric = [r for r in runs if r["group"] in ("numeric", "design --set") and "rc" in r]
    explorer = [r for r in runs if r["group"] == "explorer"]
    slowest = max(timed, key=lambda r: r["time_s"], default=None)
    return {
        "benchmark": "input_audit",
        "target": "every non-regular or over-size input refused in one line within 2 s; 0 tracebacks; 0 hangs",
        "inputs_tried": len(inputs),
        "inputs_handled": sum(r["handled"] for r in inputs),
        "refused_in_one_line_naming_the_input": sum(r["verdict"] == "refused in one line" for r in inputs),
        "handled_within_2_s": sum(r["time_s"] <= TARGET_S for r in timed),
        "worst_time_s": slowest["time_s"] if slowest else 0.0,
        "worst_time_input": f"{slowest['input']} ({slowest['bad']})" if slowest else None,
        "explorer_requests_tried": len(explorer),
        "explorer_refused_4xx": sum(r["verdict"] == "refused" for r in explorer),
        "numeric_values_tried": len(numeric),
        "numeric_refused_in_one_line": sum(r["verdict"] == "refused in one line" for r in numeric),
        "numeric_accepted": sum(r["verdict"] in ("accepted", "running") for r in numeric),
        "tracebacks": sum(r["verdict"] == "traceback" for r in runs),
        "hangs": sum(r["verdict"] == "hang" for r in runs),
        "options_without_a_probe": [r["input"] for r in runs if r["verdict"] == "no base line"],
        "findings": [
            {k: v for k, v in r.items() if k != "stdout"}
            for r in runs
            if (r["group"] in ("file", "folder") and not r["handled"])
            or r["verdict"] in ("traceback", "hang", "other", "refused for another reason", "not refused")
            and r["group"] not in ("file", "folder")
        ],
        "runs": runs,
    }


def warm() -> None:
    """Import what the commands import lazily, once, in the parent: a run's time is then uwlab's own work (and
    the machine's load), not the libraries' first import."""
    import importlib

    for name in ("pandas", "pyarrow.parquet", "scipy.optimize", "cv2", "matplotlib.pyplot", "emcee", "tifffile"):
        try:
            importlib.import_module(name)
        except ImportError:
            pass


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--details", action="store_true", help="also print every run")
    parser.add_argument("--only", action="append", choices=GROUPS, help="run only these groups (repeatable)")
    args = parser.parse_args()
    summary = campaign(tuple(args.only or GROUPS))
    if not args.details:
        summary.pop("runs")
    print(json.dumps(summary, indent=1))
