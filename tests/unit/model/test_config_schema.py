"""The config-schema layer (`uwlab.model.schema`): bad inputs of every config kind give one `ConfigError` line
naming the dotted key and the value (through the CLI: exit 2, one stderr line, no traceback); wrong units are
caught by the plausibility limits; every shipped config validates to the values it states, with the defaults
the validators had before the schemas."""

import shutil
import tomllib

import numpy as np
import pytest

from uwlab.sim.scene import RigScene, load_scene
from uwlab.model.config import design_sections
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.calibration.fit import load_fit_config
from uwlab.experiments.saturation import POINT_SATURATED_FRACTION
from uwlab.model.bench import is_bench
from uwlab.model.components import load_lens_profile
from uwlab.model.config import apply_override, validate
from uwlab.model.build import build_design
from uwlab.model.schema import (
    ExposureUs,
    FocalLengthMm,
    FrameCount,
    GainDb,
    PixelSizeUm,
    WavelengthNm,
    check,
    limits_of,
)
from uwlab.model.sensor import load_sensor_profile

from tests.support.cli import one_line_error
from tests.support.paths import EXAMPLE, ROOT

CONFIGS = ROOT / "configs"
RIG = CONFIGS / "rigs" / "sim-tank.toml"
UNIT = "is the unit right?"


def read(path) -> dict:
    with open(path, "rb") as fh:
        return tomllib.load(fh)


def assert_one_line(error: ConfigError, key: str, value, words: str) -> None:
    assert error.key == key
    assert "\n" not in str(error)
    assert str(error).startswith(f"{key} = {value!r}: ")
    assert words in error.reason


# --- Bad inputs: design, sensor profile, [sim], plan, fit, single values -----------------------------------------


@pytest.mark.parametrize(
    "dotted, value, key, shown, words",
    [
        ("lens.focal_length_mm", 0.03, "lens.focal_length_mm", 0.03, UNIT),  # metres written as mm: FOV 179°
        ("operation.altitude_m", 1e308, "operation.altitude_m", 1e308, UNIT),
        ("operation.altitude_m", 15000.0, "operation.altitude_m", 15000.0, UNIT),  # deeper than the ocean
        ("light.luminous_flux_lm", 3e7, "light.luminous_flux_lm", 3e7, UNIT),
        ("lens.f_number", 0.1, "lens.f_number", 0.1, UNIT),
        ("spectral.start_nm", 0.38, "spectral.start_nm", 0.38, UNIT),  # µm written as nm
        ("housing.dome_radius_mm", 0.05, "housing.dome_radius_mm", 0.05, UNIT),
        ("operation.circle_of_confusion_mm", 5.0, "operation.circle_of_confusion_mm", 5.0, UNIT),
        ("target.reflectance", 90, "target.reflectance", 90, "not a percentage"),
        ("sensor.gain_db", 1000.0, "sensor.gain_db", 1000.0, UNIT),
        ("operation.exposure_s", 200.0, "operation.exposure_s", 200.0, "IMX250M's range"),  # µs written as s
        ("operation.exposure_s", "fast", "operation.exposure_s", "fast", '"max-blur"'),
        ("light.count", 2.5, "light.count", 2.5, "integer"),
        ("lens.f_number", float("inf"), "lens.f_number", float("inf"), "finite"),
        ("lens.f_number", "2", "lens.f_number", "2", "number"),
        ("lens.f_number", True, "lens.f_number", True, "number"),
        ("lens.zoom", 2, "lens.zoom", 2, "unknown key; allowed: focal_length_mm, f_number, transmittance"),
        ("spectral.stop_nm", 300.0, "spectral.stop_nm", 300.0, "must exceed start_nm"),
    ],
)
def test_bad_design_values_name_the_key(example_raw, dotted, value, key, shown, words):
    apply_override(example_raw, dotted, value)
    with pytest.raises(ConfigError) as info:
        build_design(example_raw)
    assert_one_line(info.value, key, shown, words)


def test_mutually_exclusive_keys_are_refused(example_raw, tmp_path):
    """A light placed with both a beam angle in water and one in air, a lens profile with both a number and a CSV
    for its transmittance: one line naming the first key."""
    example_raw["model"] = {"kind": "extended"}
    example_raw["lights"] = [
        {"position_m": [0.0, -0.2, 0.0], "beam_half_angle_deg": 30.0, "beam_half_angle_in_air_deg": 40.0}
    ]
    with pytest.raises(ConfigError) as info:
        build_design(example_raw)
    assert_one_line(
        info.value,
        "lights[0].beam_half_angle_deg",
        30.0,
        "give at most one of beam_half_angle_deg and beam_half_angle_in_air_deg",
    )
    lens = tmp_path / "lens.toml"
    lens.write_text('name = "L"\nfocal_length_mm = 12\ntransmittance = 0.9\ntransmittance_csv = "t.csv"\n')
    with pytest.raises(ConfigError) as info:
        load_lens_profile(lens)
    assert "transmittance = 0.9: give at most one of transmittance and transmittance_csv" in str(info.value)


def test_missing_sections_and_required_keys(example_raw):
    with pytest.raises(ConfigError) as info:
        validate({**example_raw, "camera": {"zoom": 2}})
    assert_one_line(info.value, "camera", {"zoom": 2}, "allowed: spectral, light, water")
    del example_raw["lens"]
    with pytest.raises(ConfigError) as info:
        validate(example_raw)
    assert_one_line(info.value, "lens.focal_length_mm", None, "missing (required)")
    with pytest.raises(ConfigError) as info:
        validate([1, 2])
    assert_one_line(info.value, "config", [1, 2], "must be a table")


def test_grid_arrays_are_checked_element_wise(example_raw):
    mesh = np.array([10.0, 20.0, 0.03, 0.01]).reshape(1, 4, 1)  # an open-mesh axis, as `--grid` builds
    example_raw["lens"]["focal_length_mm"] = mesh
    with pytest.raises(ConfigError) as info:
        validate(example_raw)
    assert_one_line(info.value, "lens.focal_length_mm", 0.03, UNIT)  # the first offending element
    example_raw["lens"]["focal_length_mm"] = np.array([8, 30])
    good = validate(example_raw)["lens"]["focal_length_mm"]
    assert good.dtype == float and good.tolist() == [8.0, 30.0]
    example_raw["spectral"] = {"step_nm": np.array([1.0, 2.0])}
    with pytest.raises(ConfigError) as info:
        validate(example_raw)
    assert_one_line(info.value, "spectral.step_nm", [1.0, 2.0], "cannot be varied in a grid")


@pytest.mark.parametrize(
    "key, value, shown, words",
    [
        ("pixel_size_um", 3450, 3450, UNIT),  # nm written as µm
        ("pixel_size_um", 0.00345, 0.00345, UNIT),  # mm written as µm
        ("K_dn_per_e", 0, 0, "DN/e-"),
        ("exposure_max_us", 10, 10.0, "must exceed exposure_min_us"),
        ("bit_depth", 12.5, 12.5, "integer"),
        ("resolution_px", [2448], [2448], "too few items"),
        ("resolution_px", [2448, 2048, 3], [2448, 2048, 3], "at most 2 items"),
        ("prnu_percent", 150, 150, "a percentage"),
        ("colour", True, True, "unknown key"),
    ],
)
def test_bad_sensor_profiles_name_the_file_and_key(tmp_path, key, value, shown, words):
    text = (CONFIGS / "sensors" / "imx250m.toml").read_text()
    lines = [line for line in text.splitlines() if not line.startswith(f"{key} =")]
    head = lines.index("[provenance]")
    lines.insert(head - 1, f"{key} = {value!r}".replace("True", "true"))
    (tmp_path / "bad.toml").write_text("\n".join(lines) + "\n")
    shutil.copy(CONFIGS / "sensors" / "imx250m_qe.csv", tmp_path)
    with pytest.raises(ConfigError) as info:
        load_sensor_profile(str(tmp_path / "bad.toml"))
    assert_one_line(info.value, f"sensor profile bad.toml: {key}", shown, words)


@pytest.mark.parametrize(
    "key, value, words",
    [
        ("seed", -1, "integer"),
        ("light_gamma", 0, "(0, 10]"),
        ("surround_reflectance", 5.0, "not a percentage"),
        ("board_size_m", [0.15], "too few items"),
        ("board_size_m", [0.15, 0.0], UNIT),
        ("seeed", 1, "unknown key"),
    ],
)
def test_bad_sim_section_names_the_key(key, value, words):
    raw = read(RIG)
    raw["sim"][key] = value
    shown = 0.0 if value == [0.15, 0.0] else value
    with pytest.raises(ConfigError) as info:
        RigScene.from_dict(raw, RIG.parent)
    assert_one_line(info.value, f"sim.{key}", shown, words)


PLAN = f'name = "unit"\nrig = "{RIG}"\n[camera]\npixel_format = "Mono12"\nwindow = [1192, 1000, 32, 32]\n'
SWEEP = '[[sweep]]\nid = "a"\nkind = "exposure"\nvalues = [100]\n'


@pytest.mark.parametrize(
    "text, key, shown, words",
    [
        (SWEEP + "frames_per_point = 200000", "sweep.a.frames_per_point", 200000, "[2, 10000] frames"),
        (SWEEP + "dark_frames = 1", "sweep.a.dark_frames", 1, "[2, 10000] frames"),
        (SWEEP + "exposure_us = 0.5", "sweep.a.exposure_us", 0.5, UNIT),  # seconds or ms as µs
        (SWEEP + "lens = {focal_length_mm = 0.03, f_number = 2.0}", "sweep.a.lens.focal_length_mm", 0.03, UNIT),
        (SWEEP + "spectrometer_integration_ms = 0.01", "sweep.a.spectrometer_integration_ms", 0.01, "[1, 10000] ms"),
        (SWEEP + "camera = {timeout_s = 0}", "sweep.a.camera.timeout_s", 0, "[0.01, 600] s"),
        (SWEEP + 'roi = "auto"', "sweep.a.roi", "auto", '"aruco"'),
        (SWEEP + 'lens = "nonee"', "sweep.a.lens", "nonee", '"none"'),
        (SWEEP + 'spectrometer = ["camera", "camera"]', "sweep.a.spectrometer", ["camera", "camera"], "distinct"),
        (SWEEP.replace("[100]", "{start = 0, stop = inf, num = 3}"), "sweep.a.values.stop", float("inf"), "finite"),
        (SWEEP.replace("[100]", "{start = 0, stop = 10, num = 3, step = 1}"), "sweep.a.values.step", 1, "unknown key"),
        (SWEEP.replace("[100]", '"all"'), "sweep.a.values", "all", "{start, stop, num, spacing}"),
        (SWEEP.replace("[100]", "[]"), "sweep.a.values", [], "at least 1 item "),
        (SWEEP.replace('id = "a"\n', ""), "sweep[0].id", None, "missing (required)"),
        ("[defaults]\ncolour = 1\n" + SWEEP, "defaults.colour", 1, "unknown key"),
        ('[instruments]\nprotocol = "scpi"\n' + SWEEP, "instruments.protocol", "scpi", "'uwlab-ascii'"),
        ("", "sweep", None, "missing (required)"),
    ],
)
def test_bad_plans_name_the_key(tmp_path, text, key, shown, words):
    path = tmp_path / "plan.toml"
    path.write_text(PLAN + text)
    with pytest.raises(ConfigError) as info:
        load_plan(path)
    assert_one_line(info.value, key, shown, words)


@pytest.mark.parametrize(
    "line, new, key, shown, words",
    [
        ("sigma = 0.0174", "sigma = -1", "parameters.K_dn_per_e:imx250m.sigma", -1, "> 0"),
        ('kind = "halfnormal"', 'kind = "gamma"', "parameters.discrepancy.kind", "gamma", "'normal', 'lognormal'"),
        ("walkers = 32", "walkers = 7", "sampler.walkers", 7, "[8, 10000]"),
        ("walkers = 32", "walkers = 9", "sampler.walkers", 9, "even"),
        ("seed = 1", "seed = -1", "sampler.seed", -1, "integer"),
        ("train = ", "train = 1 #", "holdout.train", 1, "must be a list"),
        ("[holdout]", '[holdout]\nfolds = "two"', "holdout.folds", "two", 'a number of folds or "loo"'),
        ("[holdout]", "[holdout]\nfolds = 1", "holdout.folds", 1, "[2, 100]"),
        (
            "[parameters.light_efficiency]",
            "walkers = 32\n[parameters.light_efficiency]",
            "walkers",
            32,
            "unknown key; allowed: parameters, sampler, holdout",
        ),
    ],
)
def test_bad_fit_configs_name_the_key(tmp_path, line, new, key, shown, words):
    text = (CONFIGS / "fit" / "default.toml").read_text()
    assert line in text
    path = tmp_path / "fit.toml"
    path.write_text(text.replace(line, new, 1))
    with pytest.raises(ConfigError) as info:
        load_fit_config(path)
    assert_one_line(info.value, key, shown, words)


@pytest.mark.parametrize(
    "quantity, value, option",
    [
        (WavelengthNm, 0.55, "--wavelength-nm"),  # µm: η > 1 follows
        (WavelengthNm, 550e-9, "--wavelength-nm"),  # m
        (PixelSizeUm, 3450.0, "--pixel-size-um"),  # nm
        (ExposureUs, 0.1, "--exposure-us"),
        (GainDb, 1000.0, "--gain-db"),
        (FocalLengthMm, 5000.0, "lens.focal_length_mm"),
    ],
)
def test_single_values_go_through_the_named_quantities(quantity, value, option):
    with pytest.raises(ConfigError) as info:
        check(quantity, value, option)
    limits = limits_of(quantity)
    assert_one_line(info.value, option, value, f"[{limits.lo:g}, {limits.hi:g}]")
    assert check(quantity, np.float64(limits.lo), option) == limits.lo  # numpy scalars are numbers


def test_frame_count_refuses_before_allocating():
    with pytest.raises(ConfigError):
        check(FrameCount, 200000, "frames")
    assert check(FrameCount, 4.0, "frames") == 4 and isinstance(check(FrameCount, 4.0, "frames"), int)


@pytest.mark.parametrize(
    "argv, key",
    [
        (["design", str(EXAMPLE), "--set", "lens.focal_length_mm=0.03"], "lens.focal_length_mm = 0.03"),
        (["design", str(EXAMPLE), "--set", "operation.altitude_m=1e308"], "operation.altitude_m = 1e+308"),
        # the probe: exit 0 with a minimum f-number of −4087 before the lower limit
        (["design", str(EXAMPLE), "--set", "operation.altitude_m=1e-308"], "operation.altitude_m = 1e-308"),
        (["design", str(EXAMPLE), "--set", "light.distance_m=1e-6"], "light.distance_m = 1e-06"),
        (["design", str(EXAMPLE), "--set", "light.luminous_flux_lm=1e-300"], "light.luminous_flux_lm = 1e-300"),
        (["design", str(EXAMPLE), "--set", "lens.transmittance=1e-300"], "lens.transmittance = 1e-300"),
        (["design", str(EXAMPLE), "--set", "housing.port_transmittance=1e-300"], "housing.port_transmittance"),
        (["design", str(EXAMPLE), "--set", "light.beam_half_angle_deg=1e-300"], "light.beam_half_angle_deg"),
        (["design", str(EXAMPLE), "--set", "operation.max_blur_px=1e-300"], "operation.max_blur_px = 1e-300"),
        (["design", str(EXAMPLE), "--grid", "operation.altitude_m=1e-308,2"], "operation.altitude_m = 1e-308"),
        (["design", str(EXAMPLE), "--grid", "lens.focal_length_mm=0:inf:1"], "lens.focal_length_mm"),
        (["design", str(EXAMPLE), "--grid", "lens.focal_length_mm=10,0.03"], "lens.focal_length_mm = 0.03"),
        (["emva", "characterize", "DS", "--wavelength-nm", "0.55"], "--wavelength-nm = 0.55"),
        # numeric flags through the same named quantities: a negative seed was a numpy traceback, 1e9 frames or
        # poses a run without end
        (["grab", "--frames", "1000000000"], "frames = 1000000000"),
        (["sim", "camera", "--gige", "--seed", "-1"], "--seed = -1"),
        (["sim", "charuco", str(EXAMPLE), "--medium", "water", "--out", "unused", "--seed", "-1"], "--seed = -1"),
        (["sim", "charuco", str(EXAMPLE), "--medium", "water", "--out", "unused", "--poses", "100000000"], "--poses"),
        (["demo", "--seed", "-5", "--out", "unused"], "--seed = -5"),
        (["emva", "characterize", "DS", "--pixel-size-um", "3450"], "--pixel-size-um = 3450.0"),
    ],
)
def test_cli_exits_2_with_one_line(argv, key, capsys):
    assert key in one_line_error(capsys, argv)


def test_sweep_with_absurd_frames_is_refused_before_the_dataset_exists(tmp_path, capsys):
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN + SWEEP + "frames_per_point = 200000\n")
    out = tmp_path / "ds"
    err = one_line_error(capsys, ["sweep", str(plan), "--sim", "--out", str(out)])
    assert "sweep.a.frames_per_point = 200000" in err and not out.exists()


# --- Round trips: the shipped configs validate to what they state, defaults as before ---------------------------

# The defaults of the validators the schemas replaced (model/config.py SCHEMA, scene.py SIM_SCHEMA, plan.py
# SWEEP_DEFAULTS, fit.py load_fit_config, the sensor profile's optional keys).
DESIGN_DEFAULTS = {
    "spectral": {"start_nm": 380.0, "stop_nm": 780.0, "step_nm": 1.0},
    "light": {
        "spectrum": "generic-led",
        "beam_half_angle_deg": None,
        "beam_half_angle_in_air_deg": None,
        "beam_model": "cone",
        "count": 1,
        "distance_m": None,
        "incidence_deg": 0.0,
    },
    "water": {"attenuation_scale": 1.0},
    "housing": {
        "port": "flat",
        "water_index": 1.333,
        "port_index": 1.49,
        "port_transmittance": "fresnel",
        "dome_radius_mm": None,
        "dome_thickness_mm": None,
        "dome_decenter_mm": [0.0, 0.0, 0.0],
        "flat_thickness_mm": 0.0,
        "flat_air_gap_mm": 0.0,
        "flat_tilt_deg": [0.0, 0.0],
    },
    "lens": {"transmittance": 1.0, "min_focus_distance_m": None},
    "sensor": {"gain_db": 0.0, "bit_depth": None, "channel": "combined"},
    "operation": {
        "speed_m_s": 0.0,
        "overlap": 0.0,
        "max_blur_px": 1.0,
        "exposure_s": "max-blur",
        "motion_axis": "y",
        "min_dof_m": None,
        "circle_of_confusion_mm": None,
    },
}
SIM_DEFAULTS = {
    "seed": 1288,
    "light_gamma": 2.2,
    "surround_reflectance": 0.05,
    "light_efficiency": 1.0,
    "board_size_m": (0.15, 0.12),
}
SWEEP_DEFAULTS = {
    "frames_per_point": 2,
    "settle_s": 0.0,
    "dark": "point",
    "spectrometer": [],
    "spectrometer_integration_ms": 10.0,
    "spectrometer_averaging": 1,
    "roi": None,
    "aruco_dictionary": "DICT_4X4_50",
    "saturation_threshold": POINT_SATURATED_FRACTION,
    "gain_db": 0.0,
    "black_level_dn": None,
    "light_level": 1.0,
    "save_frames": False,
}
SENSOR_OPTIONAL = {"dark_current_e_per_s": 0.0, "dsnu_e": 0.0, "prnu_percent": 0.0, "description": "", "color": False}


def design_round_trip(raw: dict) -> None:
    values = validate(raw)
    for section, defaults in DESIGN_DEFAULTS.items():
        for key, default in defaults.items():
            expected = raw.get(section, {}).get(key, default)
            assert values[section][key] == expected and type(values[section][key]) in (type(expected), float), key
    for section, body in raw.items():
        for index, table in enumerate(body) if isinstance(body, list) else [(None, body)]:
            got = values[section] if index is None else values[section][index]
            for key, value in table.items():
                assert got[key] in (value, tuple(value) if isinstance(value, list) else value), f"{section}.{key}"
    assert validate(values) == values


@pytest.mark.parametrize("path", sorted((CONFIGS / "design").glob("*.toml")), ids=lambda p: p.name)
def test_design_configs_round_trip(path):
    design_round_trip(read(path))


@pytest.mark.parametrize("path", sorted((CONFIGS / "rigs").glob("*.toml")), ids=lambda p: p.name)
def test_rig_configs_round_trip(path):
    raw = read(path)
    if is_bench(raw):  # the EMVA 1288 bench: its [bench] table instead of the design sections
        scene = load_scene(path)
        assert scene.design.values["bench"] == {"f_number": 8.0, **raw["bench"]}
    else:
        design_round_trip(design_sections(raw))
        scene = RigScene.from_dict(raw, path.parent)
        world = dict(scene.world)
        for key, value in raw.get("world", {}).items():
            assert world[key] == (tuple(value) if isinstance(value, list) else value), f"world.{key}"
    expected = {**SIM_DEFAULTS, **raw["sim"]}
    assert dict(scene.sim) == {k: tuple(v) if isinstance(v, list) else v for k, v in expected.items()}


@pytest.mark.parametrize("path", sorted((CONFIGS / "plans").glob("*.toml")), ids=lambda p: p.name)
def test_plans_round_trip(path):
    raw = read(path)
    plan = load_plan(path)
    assert plan.name == raw.get("name", path.stem) and plan.rig_path.resolve() == (path.parent / raw["rig"]).resolve()
    assert plan.instruments.light_port == raw["instruments"].get("light_port")
    for table, sweep in zip(raw["sweep"], plan.sweeps, strict=True):
        body = {**raw.get("defaults", {}), **table}
        for key, default in SWEEP_DEFAULTS.items():
            value, expected = getattr(sweep.table, key), body.get(key, default)
            assert (list(value) if isinstance(value, tuple) else value) == expected, key
        assert sweep.table.id == body["id"] and sweep.table.kind == body["kind"]
        assert sweep.dark_frames == body.get("dark_frames", sweep.table.frames_per_point)
        values = body["values"]
        if isinstance(values, list):
            assert sweep.values == tuple(values)
        else:
            space = np.geomspace if values.get("spacing") == "log" else np.linspace
            assert sweep.values == tuple(space(values["start"], values["stop"], values["num"]))
        camera = {**raw.get("camera", {}), **body.get("camera", {})}
        assert sweep.camera.device_id == camera.get("id") and sweep.camera.pixel_format == camera.get("pixel_format")
        assert sweep.camera.window == (tuple(camera["window"]) if "window" in camera else None)


@pytest.mark.parametrize("path", sorted((CONFIGS / "fit").glob("*.toml")), ids=lambda p: p.name)
def test_fit_configs_round_trip(path):
    raw = read(path)
    config = load_fit_config(path)
    assert config.names == tuple(raw["parameters"])
    for name, table in raw["parameters"].items():
        prior = config.priors[name]
        assert prior.kind == table["kind"]
        for key, value in table.items():
            assert getattr(prior, key) == value, f"{name}.{key}"
    sampler = {
        "walkers": max(32, 4 * len(raw["parameters"])),
        "chunk_steps": 250,
        "max_steps": 60000,
        "seed": 0,
        **raw.get("sampler", {}),
    }
    assert (config.walkers, config.sampler.chunk_steps, config.sampler.max_steps, config.sampler.seed) == (
        sampler["walkers"],
        sampler["chunk_steps"],
        sampler["max_steps"],
        sampler["seed"],
    )
    assert config.holdout.train == raw.get("holdout", {}).get("train", [])


@pytest.mark.parametrize("path", sorted((CONFIGS / "sensors").glob("*.toml")), ids=lambda p: p.stem)
def test_sensor_profiles_round_trip(path):
    raw = read(path)
    profile = load_sensor_profile(path.stem)
    for key, default in SENSOR_OPTIONAL.items():
        assert getattr(profile, key) == raw.get(key, default), key
    for key, value in raw.items():
        got = getattr(profile, key)
        assert (list(got) if isinstance(got, tuple) else got) == value, key
