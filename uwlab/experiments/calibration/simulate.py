"""Fast in-process measurement campaigns on the simulated rig, for calibration tests and benchmarks.

The frames come from the simulated camera (`uwlab.sim.devices.camera.SimSensor`) looking at the rig's scene
(`uwlab.sim.scene.RigScene`) — the same physics and noise as the simulated rig behind `uwlab sweep
--sim` — but rendered directly in a small axis-centred ROI, without the device and serial layers, so that many
campaigns (one per seed) run in seconds. Rows follow the dataset contract of `uwlab.experiments.dataset`.

The true rig differs from the nominal one (the rig config's design sections, which the fit starts from) by
`truth`: ``light_efficiency``, ``attenuation_scale``, ``beam_half_angle_deg`` (in water), ``reflectance``,
``lens_transmittance`` and ``K_dn_per_e:<profile>``, and by the world that renders it (`world`: the rig's
[world] preset replaced, by default with ``ideal``, the design model; a tank world's sensor realism included, its
light's warm-up drift not: there is no clock here).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from uwlab.sim.devices.camera import SensorConfig, SimSensor, SimTruth
from uwlab.sim.scene import RigScene
from uwlab.model.config import design_sections
from uwlab.experiments.dataset import point_row
from uwlab.experiments.frames.stack import stack_statistics
from uwlab.experiments.saturation import clip_level, sensor_clip_dn
from uwlab.model.data import config_dir, read_toml
from uwlab.model.optics import NO_LENS, LensSetting

BLACK_LEVEL_DN = 16.0  # native DN, so that dark frames are not clipped at zero
FORMAT = "Mono16"  # frames are read as Mono16 (MSB-aligned)
_DESIGN_KEYS = {
    "attenuation_scale": ("water", "attenuation_scale"),
    "beam_half_angle_deg": ("light", "beam_half_angle_deg"),
    "reflectance": ("target", "reflectance"),
    "lens_transmittance": ("lens", "transmittance"),
}


PAPER_LENSES = (NO_LENS, LensSetting(30.0, 2.0), LensSetting(12.0, 4.0))


def _switch(light: dict[str, float]) -> Callable[[], float]:
    """The light's on/off state as the simulated sensor reads it (a camera's own switch)."""
    return lambda: light["on"]


def _true_scene(raw: dict, base_dir: Path, sensor: str, lens: LensSetting, truth: dict, world: str | None) -> RigScene:
    raw = copy.deepcopy(raw)
    raw["sensor"]["profile"] = sensor
    for name, (section, key) in _DESIGN_KEYS.items():
        if name in truth:
            raw.setdefault(section, {})[key] = float(truth[name])
    if "beam_half_angle_deg" in truth:
        raw["light"].pop("beam_half_angle_in_air_deg", None)
    raw.setdefault("sim", {})["light_efficiency"] = float(
        truth.get("light_efficiency", raw.get("sim", {}).get("light_efficiency", 1.0))
    )
    scene = RigScene.from_dict(raw, base_dir, world=world)
    if lens.bare:
        scene.remove_lens()
    else:
        scene.set_lens(lens.focal_length_mm, lens.f_number)
    return scene


def simulate_campaign(
    truth: dict,
    sensors=("imx250m", "icx285alm"),
    lenses=PAPER_LENSES,
    points_per_sweep: int = 12,
    frames: int = 2,
    roi_px: int = 32,
    seed: int = 0,
    rig: str | Path | None = None,
    max_fraction: float = 1.1,
    world: str | None = "ideal",
) -> tuple[pd.DataFrame, dict]:
    """Exposure sweeps (log-spaced up to `max_fraction` of the saturation exposure) for every sensor × lens.

    Returns (points, rigs) where rigs maps sweep_id to the nominal rig config (what a fit starts from).
    """
    path = Path(rig) if rig is not None else config_dir() / "rigs" / "sim-tank.toml"
    raw = read_toml(path, "--config")
    nominal = design_sections(raw)
    rows, rigs = [], {}
    rng = np.random.default_rng(seed)
    for sensor in sensors:
        for lens in lenses:
            sweep_id = f"{sensor}-{lens.label}"
            scene = _true_scene(raw, path.resolve().parent, sensor, lens, truth, world)
            k_true = truth.get(f"K_dn_per_e:{sensor}")
            sim_truth = SimTruth.from_sensor_profile(
                scene.sensor, **scene.sensor_realism(), **({"K_dn_per_e": float(k_true)} if k_true else {})
            )
            width, height = sim_truth.resolution_px
            rate = scene.on_axis_rate_e_per_s()
            window = _centre_window(width, height, roi_px)
            light = {"on": 1.0}
            sensor_sim = SimSensor(
                sim_truth,
                _window_map(scene, window, (height, width)),
                _switch(light),
                seed=int(rng.integers(2**31)),
            )
            t_sat = sim_truth.saturation_e / rate * 1e6
            lo = max(sim_truth.exposure_min_us, 0.02 * t_sat)
            exposures = np.geomspace(
                lo, max(lo * 1.01, min(max_fraction * t_sat, sim_truth.exposure_max_us)), points_per_sweep
            )
            profile = scene.sensor  # what the experimenter knows (the truth's K may differ)
            profile_dn = sensor_clip_dn(
                profile.K_dn_per_e,
                profile.saturation_e,
                profile.dark_offset_dn + BLACK_LEVEL_DN,
                profile.bit_depth,
                FORMAT,
            )
            rigs[sweep_id] = nominal
            for index, exposure in enumerate(exposures):
                cfg = SensorConfig(float(exposure), 0.0, BLACK_LEVEL_DN, FORMAT, *window)
                light["on"] = 1.0
                images = [sensor_sim.render(cfg) for _ in range(frames)]
                clip = clip_level(FORMAT, native_bits=profile.bit_depth, profile_dn=profile_dn, image=images[0])
                bright = stack_statistics(images, clip.dn)
                light["on"] = 0.0
                dark = stack_statistics((sensor_sim.render(cfg) for _ in range(frames)), clip.dn)
                rows.append(
                    point_row(
                        sweep_id=sweep_id,
                        point_index=index,
                        kind="exposure",
                        bright=bright,
                        dark=dark,
                        clip=clip,
                        sensor_profile=sensor,
                        lens_label=lens.label,
                        focal_length_mm=lens.focal_length_mm,
                        f_number=lens.f_number,
                        exposure_us=float(exposure),
                        gain_db=0.0,
                        black_level_dn=BLACK_LEVEL_DN,
                        light_level=1.0,
                        light_on=True,
                        bit_depth=16,
                        roi_x=0,
                        roi_y=0,
                        roi_w=roi_px,
                        roi_h=roi_px,
                    )
                )
    return pd.DataFrame(rows), rigs


def _centre_window(width: int, height: int, size: int) -> tuple[int, int, int, int]:
    return ((width - size) // 2, (height - size) // 2, size, size)


def _window_map(scene: RigScene, window, full_shape):
    """The scene's rate map, rendered only where the window is (zeros elsewhere), at full resolution."""
    x, y, w, h = window

    def rate_map(shape):
        full = np.zeros(full_shape, np.float32)
        coarse = scene.electron_rate_map((full_shape[0] // 16, full_shape[1] // 16))
        ys = (np.arange(y, y + h) * coarse.shape[0]) // full_shape[0]
        xs = (np.arange(x, x + w) * coarse.shape[1]) // full_shape[1]
        full[y : y + h, x : x + w] = coarse[np.ix_(ys, xs)]
        return full

    return rate_map
