"""Rig files whose world renders exactly one known effect, for tests and benchmarks that must see a check catch it
(and not fire without it)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import tomli_w

from tests.support.paths import CONFIGS

PAPER_TANK = CONFIGS / "rigs" / "paper-tank.toml"
TANK_EFFECTS_OFF = ("beam_profile", "vignetting", "lens_transmission", "backscatter", "stray_light", "warmup_drift")


def nonlinear_sensor_rig(folder: Path, nonlinearity_at_full_well: float) -> Path:
    """The paper's tank rig (configs/rigs/paper-tank.toml) in a tank world that renders only the sensor's response
    non-linearity (charge compression of `nonlinearity_at_full_well` at full well; no DSNU, PRNU or hot pixels, no
    other effect); 0 makes it linear. Written into `folder`; returns its path."""
    raw = tomllib.loads(PAPER_TANK.read_text())
    world = raw["world"]
    world["lens_transmittance_csv"] = str((PAPER_TANK.parent / world["lens_transmittance_csv"]).resolve())
    world.update({effect: False for effect in TANK_EFFECTS_OFF})
    world.update(
        sensor_realism=True,
        nonlinearity_at_full_well=nonlinearity_at_full_well,
        dsnu_e=0.0,
        prnu_percent=0.0,
        hot_pixel_fraction=0.0,
    )
    path = folder / f"tank-nonlinearity-{nonlinearity_at_full_well:g}.toml"
    path.write_text(tomli_w.dumps(raw))
    return path
