"""Water IOPs: table values at table wavelengths, documented extension, and the beam refraction at the light port."""

import numpy as np
import pandas as pd
import pytest

from tests.support.paths import ROOT
from uwlab.model.design import build_design, evaluate
from uwlab.model.grid import WavelengthGrid
from uwlab.model.water import JERLOV_TYPES, pure_water_scattering, water_iop

GRID = WavelengthGrid(300.0, 800.0, 1.0)
DATA = ROOT / "tests" / "sim" / "data"  # reference copies with their provenance (README.md there)


@pytest.mark.parametrize("kind", JERLOV_TYPES)
def test_jerlov_values_at_table_wavelengths(kind):
    table = pd.read_csv(ROOT / "configs/water/jerlov.csv", comment="#")
    rows = table[table["water_type"].astype(str) == kind]
    iop = water_iop(f"jerlov-{kind}", GRID)
    idx = (rows["wavelength_nm"].to_numpy() - 300).astype(int)
    assert iop.a_per_m[idx] == pytest.approx(rows["a_per_m"].to_numpy(), rel=1e-12)
    assert iop.c_per_m[idx] == pytest.approx((rows["a_per_m"] + rows["b_per_m"]).to_numpy(), rel=1e-12)


def test_jerlov_anchor_cells_are_unchanged_from_the_reference():
    ref = pd.read_csv(DATA / "jerlov_iops_anchor.csv", comment="#").dropna()
    ours = pd.read_csv(ROOT / "configs/water/jerlov.csv", comment="#")
    merged = ref.merge(ours, on=["water_type", "wavelength_nm"], suffixes=("_ref", ""))
    assert len(merged) == len(ref)
    assert np.allclose(merged["a_per_m"], merged["a_per_m_ref"]) and np.allclose(
        merged["b_per_m"], merged["b_per_m_ref"]
    )


def test_red_extension_is_continuous_and_rises_with_water_absorption():
    for kind in JERLOV_TYPES:
        iop = water_iop(f"jerlov-{kind}", GRID)
        a = iop.a_per_m
        assert a[701 - 300] == pytest.approx(a[700 - 300], rel=0.03)
        assert a[760 - 300] > 2.0  # pure water's absorption band near 750 nm dominates
        assert np.all(iop.b_per_m[400:] > 0) and iop.b_per_m[780 - 300] < iop.b_per_m[700 - 300]


def test_pure_fresh_matches_pope_and_fry_and_morel():
    ref = pd.read_csv(DATA / "pure_water_absorption_pope_fry_1997.csv", comment="#")
    iop = water_iop("pure-fresh", WavelengthGrid(380.0, 727.5, 2.5))
    assert iop.a_per_m == pytest.approx(ref["a_per_m"].to_numpy(), rel=1e-12)
    assert pure_water_scattering(500.0) == pytest.approx(0.0022)
    assert pure_water_scattering(400.0) / pure_water_scattering(500.0) == pytest.approx(1.25**4.32)


def test_csv_water_and_errors(tmp_path):
    path = tmp_path / "w.csv"
    path.write_text("# synthetic\nwavelength_nm,a_per_m,b_per_m\n400,0.1,0.2\n700,0.5,0.1\n")
    iop = water_iop(str(path), WavelengthGrid())
    assert iop.c_per_m[0] == pytest.approx(0.3) and iop.c_per_m[-1] == pytest.approx(0.6)  # ends held
    assert iop.c_per_m[550 - 380] == pytest.approx(0.45)


def test_beam_half_angle_given_in_air_is_refracted(example_raw):
    example_raw["light"].pop("beam_half_angle_deg")
    example_raw["light"]["beam_half_angle_in_air_deg"] = 40.0
    in_air = evaluate(build_design(example_raw))["target_irradiance_w_m2"]
    example_raw["light"].pop("beam_half_angle_in_air_deg")
    beta_w = np.degrees(np.arcsin(np.sin(np.radians(40.0)) / 1.333))
    example_raw["light"]["beam_half_angle_deg"] = beta_w
    assert evaluate(build_design(example_raw))["target_irradiance_w_m2"] == pytest.approx(in_air)
    example_raw["light"]["beam_half_angle_in_air_deg"] = 40.0
    from uwlab.errors import ConfigError

    with pytest.raises(ConfigError, match="exactly one"):
        build_design(example_raw)
