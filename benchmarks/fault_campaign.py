"""Fault campaign against the full simulated rig (JSON on stdout).

The rig is driven exactly as the tank would be (`HardwareRig`): the camera over Aravis/GigE Vision from
``uwlab sim camera --gige`` in its own process, the light and spectrometer through pyserial on the serial
simulators' pseudo-terminals; the camera renders the light state the light simulator writes. Light-level sweeps
(each point: 4 frames, a dark stack, a spectrometer reading) run while a seeded `FaultInjector` breaks devices:

1. serial: the light or the spectrometer simulator killed (SIGKILL, light dark) and restarted on its port after
   0–1 s, until at least ``--serial-trials`` restarts happened during sweeps;
2. camera: the GigE camera server killed and restarted on its address, or frozen (SIGSTOP … SIGCONT), for
   1–``--max-outage-s`` s, until at least ``--camera-outages`` outages happened during sweeps.

Every recorded point is checked against the simulators' true-state logs (`fault_campaign.wrong_points`) and
against the images: signal / level^γ must be the same for all points of a sweep (`gamma_spread`). Targets:
0 wrong points; every sweep completes (outages within the camera's limit need no resume).

Usage: python benchmarks/fault_campaign.py [--serial-trials 20] [--camera-outages 10] [--max-outage-s 10]
       [--points 30] [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from uwlab.sim.devices.serial_sim import SerialRig, SerialSimSettings
from uwlab.errors import UwlabError
from uwlab.experiments.acquisition.fault_campaign import FaultInjector, serial_restart, wrong_points
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.rigs import HardwareRig
from uwlab.experiments.acquisition.sweep import SweepRunner
from uwlab.experiments.dataset import Dataset

ROOT = Path(__file__).resolve().parents[1]
RIG = ROOT / "configs" / "rigs" / "sim-tank.toml"
PLAN = """
name = "fault-campaign"
rig = "{rig}"
[camera]
backend = "aravis"
id = "{address}"
pixel_format = "Mono12"
window = [1192, 1000, 64, 48]
timeout_s = 2.0
[instruments]
light_port = "{light}"
spectrometer_port = "{spectrometer}"
reopen_s = 30
[defaults]
black_level_dn = 32
frames_per_point = 4
exposure_us = 400
[[sweep]]
id = "levels"
kind = "light-level"
values = {{ start = 0.4, stop = 1.0, num = {points} }}
spectrometer = ["target"]
dark = "point"
"""


class CameraServer:
    """``uwlab sim camera --gige`` in a subprocess on ``address``, lit by the light simulator's rig state."""

    def __init__(self, address: str, rig_state: Path):
        self.address, self.rig_state = address, rig_state
        self.proc = self._start()

    def _start(self) -> subprocess.Popen:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "uwlab.cli.main",
                "sim",
                "camera",
                "--gige",
                "--address",
                self.address,
                "--rig-state",
                str(self.rig_state),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        if not proc.stdout.readline():
            raise RuntimeError(f"GigE camera server on {self.address} did not start")
        return proc

    def restart_after(self, seconds: float) -> None:
        self.proc.kill()
        self.proc.wait()
        time.sleep(seconds)
        self.proc = self._start()

    def freeze_for(self, seconds: float) -> None:
        self.proc.send_signal(signal.SIGSTOP)
        time.sleep(seconds)
        self.proc.send_signal(signal.SIGCONT)

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGCONT)
        self.proc.terminate()
        self.proc.wait(timeout=30)


def camera_faults(server: CameraServer, max_outage_s: float):
    def restart(rng):
        seconds = float(rng.uniform(1.0, max_outage_s))
        server.restart_after(seconds)
        return {"fault": "camera server restart", "down_s": seconds}

    def freeze(rng):
        seconds = float(rng.uniform(1.0, max_outage_s))
        server.freeze_for(seconds)
        return {"fault": "camera server frozen", "down_s": seconds}

    return [restart, freeze]


def gamma_spread(points, gamma: float) -> float:
    ratio = points["signal_dn"] / points["light_level"] ** gamma
    return float(ratio.std() / ratio.mean())


def campaign(
    name: str,
    faults,
    wanted: int,
    every_s: tuple[float, float],
    rig_files: dict,
    serial: SerialRig,
    work: Path,
    seed: int,
    gamma: float,
) -> dict:
    """Sweeps under ``faults`` until ``wanted`` faults happened while a sweep ran."""
    trials, sweeps, completed, points_total, wrong, re_measured, spreads, errors = [], 0, 0, 0, [], 0, [], []
    while len(trials) < wanted:
        sweeps += 1
        plan_path = work / f"{name}-{sweeps}.toml"
        plan_path.write_text(PLAN.format(**rig_files))
        plan = load_plan(plan_path)
        data = Dataset.create(work / f"{name}-{sweeps}", plan.raw, plan_sha256=plan.sha256, sim=False)
        with FaultInjector(faults, seed=seed + sweeps, every_s=every_s, limit=wanted - len(trials)) as injector:
            try:
                with HardwareRig(plan, confirm=lambda message: None) as rig:
                    SweepRunner(plan, data, rig).run()
                completed += 1
            except UwlabError as exc:
                errors.append(str(exc))
            finished_ns = time.time_ns()
        trials += [t for t in injector.trials if t["t_ns"] < finished_ns]
        points = Dataset.open(work / f"{name}-{sweeps}").points()
        points_total += len(points)
        re_measured += int((points["attempts"] > 1).sum())
        wrong += wrong_points(points, serial.state_log("light").entries(), serial.state_log("spectrometer").entries())
        spreads.append(gamma_spread(points, gamma))
    return {
        "trials": len(trials),
        "faults": sorted({t["fault"] for t in trials}),
        "max_down_s": round(max(t.get("down_s", 0.0) for t in trials), 2),
        "sweeps": sweeps,
        "completed_sweeps": completed,
        "errors": errors,
        "points": points_total,
        "wrong_points": len(wrong),
        "wrong": wrong[:10],
        "re_measured_points": re_measured,
        "max_gamma_spread": round(max(spreads), 5),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--serial-trials", type=int, default=20)
    parser.add_argument("--camera-outages", type=int, default=10)
    parser.add_argument("--max-outage-s", type=float, default=10.0)
    parser.add_argument("--points", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    started = time.monotonic()
    settings = SerialSimSettings.from_config(RIG)
    with tempfile.TemporaryDirectory(prefix="uwlab-faults-") as tmp, SerialRig(Path(tmp), settings) as serial:
        work = Path(tmp)
        server = CameraServer(f"127.0.{os.getpid() % 200 + 1}.250", serial.rig_state_path)
        try:
            files = {
                "rig": RIG,
                "address": server.address,
                "light": serial.ports["light"],
                "spectrometer": serial.ports["spectrometer"],
                "points": args.points,
            }
            serial_result = campaign(
                "serial",
                [serial_restart(serial, "light", (0.0, 1.0)), serial_restart(serial, "spectrometer", (0.0, 1.0))],
                args.serial_trials,
                (0.2, 1.5),
                files,
                serial,
                work,
                args.seed,
                settings.light_gamma,
            )
            camera_result = campaign(
                "camera",
                camera_faults(server, args.max_outage_s),
                args.camera_outages,
                (0.5, 2.0),
                files,
                serial,
                work,
                args.seed + 1000,
                settings.light_gamma,
            )
        finally:
            server.stop()
    results = {"serial_restarts": serial_result, "camera_outages": camera_result}
    meets = all(
        r["wrong_points"] == 0 and r["completed_sweeps"] == r["sweeps"] and r["max_gamma_spread"] < 0.01
        for r in results.values()
    )
    print(
        json.dumps(
            {
                **results,
                "targets": {
                    "wrong_points": 0,
                    "serial_restarts_min": 20,
                    "camera_outages_min": 10,
                    "max_outage_s": args.max_outage_s,
                    "every_sweep_completes": True,
                },
                "meets_target": meets and serial_result["trials"] >= 20 and camera_result["trials"] >= 10,
                "elapsed_s": round(time.monotonic() - started, 1),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
