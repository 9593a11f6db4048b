"""Inverse design against brute-force grid searches, closed forms and the minimality rule; infeasible problems; the
Pareto front; the calibrated posterior's probabilities against an independent Monte Carlo."""

import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from tests.support.cli import one_line_error
from tests.support.paths import EXAMPLE
from uwlab.cli.main import main
from uwlab.errors import ConfigError
from uwlab.experiments.design.posterior import credible_band, load_posterior
from uwlab.experiments.design.solve import (
    FreeKey,
    Objective,
    Problem,
    output_value,
    parse_free,
    parse_requirement,
    solve,
)
from uwlab.model.build import build_design
from uwlab.model.evaluation import evaluate

AUV = {
    "operation.altitude_m": 2.0,
    "water.type": "jerlov-I",
    "lens.focal_length_mm": 12.0,
    "operation.exposure_s": "max-blur",
}
DOF = ["dof_m.near <= 1.7", "dof_m.far >= 2.3"]
LIGHT = ["snr_db >= 30", "mean_fraction >= 0.25", "mean_fraction <= 0.6"]
LUMENS = FreeKey("light.luminous_flux_lm", 100.0, 100_000.0)
F_NUMBER = FreeKey("lens.f_number", 1.4, 22.0)


@pytest.fixture
def auv_raw(example_raw):
    for dotted, value in AUV.items():
        section, key = dotted.split(".")
        example_raw[section][key] = value
    return example_raw


def problem(raw, free, requirements, objectives, **kw):
    return Problem(
        raw,
        EXAMPLE.parent,
        free,
        [parse_requirement(r) for r in requirements],
        [Objective(k, s) for s, k in objectives],
        **kw,
    )


def meets(raw, values: dict, requirements) -> np.ndarray:
    """The test's own feasibility check: evaluate the design and compare each output with its bound."""
    out = evaluate(build_design(raw, EXAMPLE.parent).with_values(**values))
    ok = True
    for text in requirements:
        r = parse_requirement(text)
        x = output_value(out, r.output)
        ok = ok & ((x >= r.value) if r.op == ">=" else (x <= r.value))
    return np.asarray(ok)


def test_one_free_key_matches_the_linear_closed_form(auv_raw):
    """Below saturation the response is linear in the flux: mean_fraction(Φ) = (dark + a Φ) / full."""
    auv_raw["lens"]["f_number"] = 4.0
    result = solve(problem(auv_raw, [LUMENS], ["mean_fraction >= 0.25"], [("minimize", LUMENS.key)]))
    design = build_design(auv_raw, EXAMPLE.parent)
    full = 2.0 ** design["sensor.bit_depth"] - 1
    dark = design.sensor.dark_offset_dn
    slope = (float(evaluate(design)["mean_dn"]) - dark) / design["light.luminous_flux_lm"]
    solution = result.solutions[0]
    assert result.feasible and solution.minimal and solution.active == ["mean_fraction >= 0.25"]
    assert solution.values[LUMENS.key] == pytest.approx((0.25 * full - dark) / slope, rel=1e-9)


def test_two_free_keys_against_brute_force(auv_raw):
    """Least lumens with the f-number free: the solver's answer against a 4000 × 1000 grid search."""
    requirements = LIGHT + DOF
    result = solve(problem(auv_raw, [LUMENS, F_NUMBER], requirements, [("minimize", LUMENS.key)]))
    lumens = np.geomspace(LUMENS.lo, LUMENS.hi, 4000)[:, None]
    f_numbers = np.geomspace(F_NUMBER.lo, F_NUMBER.hi, 1000)[None, :]
    ok = meets(auv_raw, {LUMENS.key: lumens, F_NUMBER.key: f_numbers}, requirements)
    brute = float(np.broadcast_to(lumens, ok.shape)[ok].min())
    solution = result.solutions[0].values
    assert meets(auv_raw, solution, requirements)  # feasible, so not below the true minimum
    step = (F_NUMBER.hi / F_NUMBER.lo) ** (1 / 999)  # the grid's f-number step costs up to step² in lumens
    assert brute / step**2 / 1.002 <= solution[LUMENS.key] <= brute
    assert set(result.solutions[0].active) == {"mean_fraction >= 0.25", "dof_m.near <= 1.7"}


def test_the_solution_is_minimal_one_percent_less_breaks_a_requirement(auv_raw):
    requirements = LIGHT + DOF
    result = solve(problem(auv_raw, [LUMENS, F_NUMBER], requirements, [("minimize", LUMENS.key)]))
    solution = result.solutions[0].values
    assert result.solutions[0].minimal
    f_numbers = np.geomspace(F_NUMBER.lo, F_NUMBER.hi, 20_000)
    assert meets(auv_raw, solution, requirements)
    assert not meets(auv_raw, {LUMENS.key: 0.99 * solution[LUMENS.key], F_NUMBER.key: f_numbers}, requirements).any()
    assert meets(
        auv_raw, {LUMENS.key: 0.999 * solution[LUMENS.key] / 0.99, F_NUMBER.key: solution[F_NUMBER.key]}, requirements
    )


def test_maximise_the_f_number_for_a_fixed_light(auv_raw):
    auv_raw["light"]["luminous_flux_lm"] = 40_000.0
    result = solve(problem(auv_raw, [F_NUMBER], LIGHT, [("maximize", F_NUMBER.key)]))
    n = result.solutions[0].values[F_NUMBER.key]
    grid = np.geomspace(F_NUMBER.lo, F_NUMBER.hi, 200_000)
    ok = meets(auv_raw, {F_NUMBER.key: grid}, LIGHT)
    assert grid[ok].max() == pytest.approx(n, rel=2e-5) and result.solutions[0].minimal
    assert not meets(auv_raw, {F_NUMBER.key: 1.01 * n}, LIGHT)


def test_pareto_front_points_are_brute_force_minima(auv_raw):
    requirements = LIGHT + DOF
    result = solve(
        problem(auv_raw, [LUMENS, F_NUMBER], requirements, [("minimize", LUMENS.key), ("maximize", F_NUMBER.key)])
    )
    front = [s.values for s in result.solutions]
    assert len(front) >= 8
    lumens = np.geomspace(LUMENS.lo, LUMENS.hi, 200_000)
    for point in front:
        ok = meets(auv_raw, {LUMENS.key: lumens, F_NUMBER.key: point[F_NUMBER.key]}, requirements)
        assert lumens[ok].min() == pytest.approx(point[LUMENS.key], rel=1e-4)
    n = np.array([p[F_NUMBER.key] for p in front])
    lm = np.array([p[LUMENS.key] for p in front])
    assert np.all(np.diff(n) > 0) and np.all(np.diff(lm) > 0)  # a trade-off: more f-number costs light
    assert all(s.minimal and s.pareto for s in result.solutions)
    # the ends: the DoF sets the smallest f-number, the light's upper bound the largest
    assert not meets(auv_raw, {LUMENS.key: LUMENS.hi, F_NUMBER.key: 0.995 * n[0]}, requirements)
    assert lm[-1] == pytest.approx(LUMENS.hi, rel=1e-6)


def test_infeasible_names_the_requirement_that_fails_even_at_the_bounds(auv_raw):
    result = solve(
        problem(
            auv_raw,
            [FreeKey(LUMENS.key, 100.0, 1000.0)],
            ["snr_db >= 30", "dof_m.near <= 1.8"],
            [("minimize", LUMENS.key)],
        )
    )
    assert not result.feasible
    assert [u["requirement"] for u in result.unmet] == ["snr_db >= 30"]
    best = result.unmet[0]
    assert best["at"][LUMENS.key] == pytest.approx(1000.0)
    assert best["best"] == pytest.approx(
        float(evaluate(build_design(auv_raw, EXAMPLE.parent).with_values(**{LUMENS.key: 1000.0}))["snr_db"]), rel=1e-9
    )


def test_infeasible_pair_of_requirements(auv_raw):
    result = solve(
        problem(auv_raw, [LUMENS], ["mean_fraction >= 0.5", "mean_fraction <= 0.3"], [("minimize", LUMENS.key)])
    )
    assert not result.feasible and result.unmet == []
    assert result.conflicting == [["mean_fraction >= 0.5", "mean_fraction <= 0.3"]]


def write_fit(tmp_path, efficiency, discrepancy=None, k=None):
    columns = {"light_efficiency": efficiency}
    if discrepancy is not None:
        columns["discrepancy"] = discrepancy
    if k is not None:
        columns["K_dn_per_e:imx250m"] = k
    pd.DataFrame(columns).to_parquet(tmp_path / "samples.parquet")
    return tmp_path


def test_probability_of_the_solution_against_an_independent_monte_carlo(auv_raw, tmp_path):
    """Light efficiency ~ lognormal(ln 0.8, 0.15): the solver's lumens for P(mean_fraction >= 0.25) >= 0.9 meet
    the requirement in 90 % of fresh draws from that distribution, and the closed-form quantile agrees."""
    auv_raw["lens"]["f_number"] = 4.0
    rng = np.random.default_rng(11)
    fit = write_fit(tmp_path, rng.lognormal(np.log(0.8), 0.15, 20_000))
    loader = lambda design: load_posterior(fit, design, max_samples=2000)  # noqa: E731
    result = solve(
        problem(
            auv_raw,
            [LUMENS],
            ["mean_fraction >= 0.25"],
            [("minimize", LUMENS.key)],
            posterior_loader=loader,
            confidence=0.9,
        )
    )
    solution = result.solutions[0]
    assert solution.probability >= 0.9 and solution.minimal
    lumens = solution.values[LUMENS.key]
    fresh = np.random.default_rng(99).lognormal(np.log(0.8), 0.15, 200_000)
    met = meets(auv_raw, {LUMENS.key: lumens * fresh}, ["mean_fraction >= 0.25"])
    assert met.mean() == pytest.approx(0.9, abs=0.015)
    design = build_design(auv_raw, EXAMPLE.parent)
    full, dark = 2.0 ** design["sensor.bit_depth"] - 1, design.sensor.dark_offset_dn
    slope = (float(evaluate(design)["mean_dn"]) - dark) / design["light.luminous_flux_lm"]
    quantile = stats.lognorm(0.15, scale=0.8).ppf(0.1)
    assert lumens == pytest.approx((0.25 * full - dark) / (slope * quantile), rel=0.02)


def test_joint_probability_with_discrepancy_and_gain(auv_raw, tmp_path):
    """Two requirements and three uncertain factors: the probability the solver reports at its solution equals
    a Monte Carlo over the same factors computed here from the chain's linearity in flux and K."""
    auv_raw["lens"]["f_number"] = 4.0
    rng = np.random.default_rng(5)
    n = 3000
    efficiency = rng.lognormal(np.log(0.9), 0.1, n)
    delta, k = np.abs(rng.normal(0.05, 0.02, n)), rng.normal(0.35, 0.02, n)
    fit = write_fit(tmp_path, efficiency, delta, k)
    loader = lambda design: load_posterior(fit, design, max_samples=n, seed=3)  # noqa: E731
    requirements = ["mean_fraction >= 0.25", "mean_fraction <= 0.6"]
    p = problem(auv_raw, [LUMENS], requirements, [("minimize", LUMENS.key)], posterior_loader=loader, confidence=0.8)
    result = solve(p)
    solution = result.solutions[0]
    design = build_design(auv_raw, EXAMPLE.parent)
    full, dark = 2.0 ** design["sensor.bit_depth"] - 1, design.sensor.dark_offset_dn
    electrons_per_lm = float(evaluate(design)["mean_electrons"]) / design["light.luminous_flux_lm"]
    z = np.random.default_rng(3).standard_normal(n)

    def monte_carlo(lumens):
        flux = lumens * efficiency * np.maximum(1 + delta * z, 0)
        dn = dark + k * np.minimum(electrons_per_lm * flux, design.sensor.saturation_e)
        fraction = np.minimum(dn, full) / full
        return np.mean((fraction >= 0.25) & (fraction <= 0.6))

    lumens = solution.values[LUMENS.key]
    probe = lumens * np.array([0.7, 0.9, 0.97, 1.03, 1.2, 1.6, 2.0])
    joint, _ = p.probabilities(LUMENS.unit(probe)[:, None])
    assert joint == pytest.approx([monte_carlo(x) for x in probe], abs=1e-12)
    assert monte_carlo(lumens * (1 + 1e-9)) >= 0.8 > monte_carlo(0.99 * lumens)
    assert solution.probability == pytest.approx(0.8, abs=1.5 / n)


def test_credible_band_is_the_percentiles_of_the_scaled_response(example_raw, tmp_path):
    rng = np.random.default_rng(2)
    efficiency = rng.lognormal(np.log(0.8), 0.2, 4000)
    fit = write_fit(tmp_path, efficiency)
    example_raw["operation"]["exposure_s"] = 1e-4
    design = build_design(example_raw, EXAMPLE.parent)
    band = credible_band(design, load_posterior(fit, design))
    kept = efficiency[np.unique(np.linspace(0, 3999, 1000).round().astype(int))]
    dark = design.sensor.dark_offset_dn
    nominal = float(evaluate(design)["mean_dn"])
    for name, q in (("p2_5", 2.5), ("median", 50), ("p97_5", 97.5)):
        assert band["mean_dn"][name] == pytest.approx(dark + (nominal - dark) * np.percentile(kept, q), rel=1e-9)
    assert band["samples"] == 1000 and band["carried"] == ["light_efficiency"]


def test_posterior_directory_must_hold_samples(example_raw, tmp_path):
    with pytest.raises(ConfigError, match="samples.parquet"):
        load_posterior(tmp_path, build_design(example_raw, EXAMPLE.parent))


WORKED = [
    "design",
    "solve",
    str(EXAMPLE),
    "--set",
    "operation.altitude_m=2",
    "--set",
    "water.type=jerlov-I",
    "--set",
    "lens.focal_length_mm=12",
    "--set",
    "operation.exposure_s=max-blur",
    "--free",
    "light.luminous_flux_lm=100:100000",
    "--free",
    "lens.f_number=1.4:22",
    "--require",
    "snr_db >= 30",
    "--require",
    "mean_fraction >= 0.25",
    "--require",
    "mean_fraction <= 0.6",
    "--require",
    "dof_m.near <= 1.7",
    "--require",
    "dof_m.far >= 2.3",
    "--minimize",
    "light.luminous_flux_lm",
]


def test_cli_single_objective_json_has_the_design_outputs(capsys):
    code = main(WORKED + ["--json"])
    answer = json.loads(capsys.readouterr().out)
    design = json.loads((main(["design", str(EXAMPLE), "--json"]), capsys.readouterr().out)[1])
    assert code == 0 and answer["feasible"] is True and answer["minimal"] is True
    assert set(answer["solution"]) == {"light.luminous_flux_lm", "lens.f_number"}
    assert set(answer["outputs"]) == set(design)
    assert answer["outputs"]["dof_m"]["near"] == pytest.approx(1.7, abs=1e-6)
    assert "dof_m.near <= 1.7" in answer["active"]


def test_cli_worked_example_front_parquet_and_plot(capsys, tmp_path):
    code = main(
        WORKED
        + [
            "--maximize",
            "lens.f_number",
            "--out",
            str(tmp_path / "front.parquet"),
            "--plot",
            str(tmp_path / "plots"),
            "--json",
        ]
    )
    answer = json.loads(capsys.readouterr().out)
    front = pd.read_parquet(tmp_path / "front.parquet")
    assert code == 0 and len(front) == len(answer["front"]) >= 8
    assert front["lens.f_number"].tolist() == [p["solution"]["lens.f_number"] for p in answer["front"]]
    assert (tmp_path / "plots" / "front.png").stat().st_size > 20_000


@pytest.mark.parametrize(
    "extra, key",
    [
        (["--free", "lens.f_number=4:2"], "--free"),
        (["--free", "lens.f_number"], "--free"),
        (["--free", "lens.fnumber=1:2"], "lens.fnumber"),
        (["--free", "lens.f_number=-1:2"], "lens.f_number"),
        (["--require", "snr_db > 30"], "--require"),
        (["--require", "snr_dbb >= 30"], "snr_dbb"),
        (["--require", "dof_m >= 1"], "dof_m.near"),
        (["--require", "saturated <= 0"], "flag"),
        (["--maximize", "sensor.gain_db"], "sensor.gain_db"),
        (["--out", "front.txt"], "--out"),
        (["--confidence", "0.9"], "--posterior"),
        (["--posterior", "NOWHERE"], "samples.parquet"),
    ],
)
def test_cli_solve_bad_input_is_one_line(capsys, tmp_path, extra, key):
    extra = [e.replace("NOWHERE", str(tmp_path)) for e in extra]
    assert key in one_line_error(capsys, WORKED + extra)


def test_cli_infeasible_json(capsys):
    code = main(
        WORKED[: WORKED.index("--free")]
        + [
            "--free",
            "light.luminous_flux_lm=100:1000",
            "--require",
            "snr_db >= 30",
            "--minimize",
            "light.luminous_flux_lm",
            "--json",
        ]
    )
    answer = json.loads(capsys.readouterr().out)
    assert code == 0 and answer["feasible"] is False and answer["unmet"][0]["requirement"] == "snr_db >= 30"


def test_parse_free_and_requirement():
    assert parse_free("lens.f_number=1.4:22") == FreeKey("lens.f_number", 1.4, 22.0)
    r = parse_requirement(" dof_m.far>=2.3 ")
    assert (r.output, r.op, r.value) == ("dof_m.far", ">=", 2.3)


def test_cli_design_posterior_band_and_solve_needs_a_config(capsys, tmp_path):
    fit = write_fit(tmp_path, np.random.default_rng(4).lognormal(np.log(0.8), 0.2, 500))
    code = main(["design", str(EXAMPLE), "--posterior", str(fit), "--json"])
    band = json.loads(capsys.readouterr().out)["posterior"]
    assert code == 0 and band["samples"] == 500
    for key in ("mean_dn", "mean_fraction", "snr_db"):
        q = band[key]
        assert q["p2_5"] < q["p16"] < q["median"] < q["p84"] < q["p97_5"]
    code = main(["design", "solve"])
    captured = capsys.readouterr()
    assert code == 2 and "CONFIG" in captured.err and captured.err.count("\n") == 1
