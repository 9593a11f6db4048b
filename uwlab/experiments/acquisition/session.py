"""A sweep session: a plan run into a new dataset, or into an unfinished one (resume), on the tank's devices or the
simulated rig — what `uwlab sweep` and `uwlab.sweep` run.

The order is the safe one: the plan is validated and the dataset is created (or opened with its lock held, and
checked to come from the same plan) before any device is opened; the rig is a context manager, so the lights go to
their safe state and the simulators stop on any exit, and the dataset records whether each light read back off
(`record_safe_state`); every point is durable before the next one starts
(`uwlab.experiments.acquisition.sweep`).
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import Plan
from uwlab.experiments.acquisition.rigs import AskValue, Confirm, HardwareRig
from uwlab.experiments.acquisition.sweep import Progress, SweepRunner, open_for_resume
from uwlab.experiments.dataset import Dataset
from uwlab.outputs import output_dir

if TYPE_CHECKING:
    from uwlab.experiments.acquisition.sim_rig import SimRig


def default_out(plan: Plan) -> Path:
    """Where a plan's dataset goes by default: ``<plan file stem>-dataset`` in the working directory."""
    return Path(f"{plan.path.stem}-dataset")


def open_target(
    plan: Plan,
    out: str | Path | None = None,
    *,
    resume: bool = False,
    sim: bool = False,
    force: bool = False,
    purpose: str = "uwlab sweep",
) -> Dataset:
    """The dataset a session writes, its lock held, checked before any device is opened: a new one at `out`
    (default `default_out`; `force` replaces an existing one), or with `resume` the unfinished dataset at `out`
    (same plan, passing its check)."""
    if resume:
        if out is None:
            raise ConfigError("--resume", None, "give the dataset directory to complete")
        output_dir(out, "--resume")
        return open_for_resume(out, plan, sim, purpose=f"{purpose} --resume")
    target = output_dir(default_out(plan) if out is None else out, "--out")
    return Dataset.create(target, plan.raw, plan_sha256=plan.sha256, sim=sim, force=force, purpose=purpose)


def make_rig(
    plan: Plan, sim: bool, confirm: Confirm | None = None, seed: int = 0, ask_value: AskValue | None = None
) -> SimRig | HardwareRig:
    """The rig the plan runs on: the simulated one (`SimRig`, its noise seeded from `seed`) or the tank's devices
    (`HardwareRig`; `confirm` asks the operator for manual steps and `ask_value` for settings made by hand, the lens
    focus and the target's distance; None refuses them)."""
    if sim:
        from uwlab.experiments.acquisition.sim_rig import SimRig

        return SimRig(plan.rig_path, seed=seed, lights=plan.lights)
    return HardwareRig(plan, confirm, ask_value)


def progress_text(event: Progress) -> str:
    """The latest point in a few words, for a progress bar's postfix: ``exposure#3 t=200us signal=812.4DN``."""
    latest = event.latest
    signal = "n/a" if latest.get("signal_dn") is None else f"{latest['signal_dn']:.1f}"
    return (
        f"{event.sweep_id}#{event.point_index} t={latest['exposure_us']:g}us signal={signal}DN"
        f"{' SAT' if latest.get('saturated') else ''}"
    )


def run_session(
    plan: Plan,
    out: str | Path | None = None,
    *,
    resume: bool = False,
    sim: bool = False,
    force: bool = False,
    confirm: Confirm | None = None,
    seed: int = 0,
    progress: Callable[[Progress], None] | None = None,
    purpose: str = "uwlab sweep",
    ask_value: AskValue | None = None,
) -> Path:
    """Run every missing point of `plan` into the dataset `open_target` gives, on `make_rig`'s rig; `progress` is
    called after each recorded point. Returns the dataset's directory."""
    with open_target(plan, out, resume=resume, sim=sim, force=force, purpose=purpose) as dataset:
        rig = make_rig(plan, sim, confirm, seed, ask_value)
        try:
            with rig:
                SweepRunner(plan, dataset, rig, progress).run()
        except BaseException:
            record_safe_state(dataset, rig, quiet=True)
            raise
        record_safe_state(dataset, rig)
        return Path(dataset.root)


def record_safe_state(dataset: Dataset, rig: SimRig | HardwareRig, quiet: bool = False) -> None:
    """Write into the dataset's metadata whether each light read back in its safe state (output off) when the rig
    closed — on a normal end, an error, Ctrl-C or a lost camera alike (``lights_safe_state``: name → {off, utc}).
    ``quiet`` (an error is ending the sweep): a failure to write it does not hide that error."""
    if not rig.safe_states:
        return
    utc = datetime.now(UTC).isoformat(timespec="seconds")
    try:
        dataset.update_metadata(
            lights_safe_state={name: {"off": off, "utc": utc} for name, off in rig.safe_states.items()}
        )
    except Exception:
        if not quiet:
            raise
