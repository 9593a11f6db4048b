"""Properties of the data files in configs/ (sensors, lenses, lights, water) and of their provenance."""

from __future__ import annotations

import tomllib

import numpy as np
import pandas as pd
import pytest

from uwlab.model.data import read_csv_columns
from tests.support.paths import CONFIGS

CONFIGS = CONFIGS
SENSOR_IDS = ("imx250m", "imx250c", "icx285alm", "imx178m", "imx249m", "imx252m", "imx264c")
NUMERIC_KEYS = (
    "pixel_size_um",
    "resolution_px",
    "bit_depth",
    "K_dn_per_e",
    "dark_offset_dn",
    "dark_noise_e",
    "saturation_e",
    "exposure_min_us",
    "exposure_max_us",
    "gain_min_db",
    "gain_max_db",
)
OPTIONAL_NUMERIC_KEYS = ("dark_current_e_per_s", "dsnu_e", "prnu_percent")
REQUIRED_KEYS = ("name", "description", "color", "qe_csv", *NUMERIC_KEYS)
JERLOV_TYPES = ("I", "II", "III", "1C", "3C", "5C", "7C", "9C")
JERLOV_NM = (300, 310, 350, 375, 400, 425, 450, 475, 500, 525, 550, 575, 600, 625, 650, 675, 700)
KNOWN_GAPS = {("3C", 675), ("3C", 700), ("5C", 600), ("5C", 625), ("5C", 650), ("5C", 675), ("5C", 700)}
# Values of the reference copy tests/sim/data/pure_water_absorption_pope_fry_1997.csv.
POPE_FRY = {380.0: 0.01137, 500.0: 0.0204, 700.0: 0.624}


def sensor(sid: str) -> dict:
    with open(CONFIGS / "sensors" / f"{sid}.toml", "rb") as fh:
        return tomllib.load(fh)


def qe_table(sid: str) -> pd.DataFrame:
    return pd.read_csv(CONFIGS / "sensors" / sensor(sid)["qe_csv"], comment="#")


def jerlov() -> pd.DataFrame:
    return pd.read_csv(CONFIGS / "water" / "jerlov.csv", comment="#")


def test_sensor_profiles_are_exactly_the_seven_ids():
    assert sorted(p.stem for p in (CONFIGS / "sensors").glob("*.toml")) == sorted(SENSOR_IDS)


@pytest.mark.parametrize("sid", SENSOR_IDS)
def test_sensor_profile_has_required_keys_in_sane_ranges(sid):
    s = sensor(sid)
    assert set(REQUIRED_KEYS) <= set(s)
    assert isinstance(s["color"], bool)
    assert 1.0 <= s["pixel_size_um"] <= 20.0
    assert len(s["resolution_px"]) == 2 and all(isinstance(n, int) and 100 <= n <= 10000 for n in s["resolution_px"])
    assert s["bit_depth"] in (8, 10, 12, 14, 16)
    assert 0.01 <= s["K_dn_per_e"] <= 10.0
    assert 0.0 <= s["dark_offset_dn"] < 2 ** s["bit_depth"] / 4
    assert 0.5 <= s["dark_noise_e"] <= 50.0
    assert 1_000 <= s["saturation_e"] <= 1_000_000
    assert 0 < s["exposure_min_us"] < s["exposure_max_us"]
    assert 0.0 <= s["gain_min_db"] <= s["gain_max_db"] <= 60.0
    assert s.get("dark_current_e_per_s", 0.0) >= 0.0


@pytest.mark.parametrize("sid", SENSOR_IDS)
def test_every_numeric_key_has_provenance_and_flags_name_real_keys(sid):
    s = sensor(sid)
    numeric = [k for k in (*NUMERIC_KEYS, *OPTIONAL_NUMERIC_KEYS) if k in s]
    assert all(s["provenance"].get(k, "").strip() for k in numeric)
    for flag in ("corrected", "assumed"):
        assert set(s["flags"][flag]) <= set(s) - {"provenance", "flags"}
    assert all("assumed" in s["provenance"][k] for k in s["flags"]["assumed"])
    assert all("correct" in s["provenance"][k] for k in s["flags"]["corrected"])


@pytest.mark.parametrize("sid", SENSOR_IDS)
def test_full_scale_not_exceeded_by_more_than_three_percent_at_saturation(sid):
    s = sensor(sid)
    assert s["K_dn_per_e"] * s["saturation_e"] <= 1.03 * (2 ** s["bit_depth"] - 1)


def test_imx250c_resolution_is_corrected_to_2448_by_2048():
    assert sensor("imx250c")["resolution_px"] == [2448, 2048]
    assert "resolution_px" in sensor("imx250c")["flags"]["corrected"]


def test_same_pixel_sensors_agree_on_dark_noise_after_scale_correction():
    noise = [sensor(sid)["dark_noise_e"] for sid in ("imx250m", "imx250c", "imx252m")]
    assert max(noise) / min(noise) < 1.1


@pytest.mark.parametrize("sid", SENSOR_IDS)
def test_qe_curve_is_a_sorted_fraction_without_duplicates(sid):
    table = qe_table(sid)
    nm = table["wavelength_nm"].to_numpy()
    assert np.all(np.diff(nm) > 0)
    curves = table.drop(columns="wavelength_nm").to_numpy()
    assert not np.isnan(curves).any()
    assert curves.min() >= 0.0 and curves.max() <= 1.0
    assert nm[0] <= 410.0 and nm[-1] >= 740.0


@pytest.mark.parametrize("sid", SENSOR_IDS)
def test_qe_columns_match_colour_flag(sid):
    columns = list(qe_table(sid).columns)
    if sensor(sid)["color"]:
        assert columns == ["wavelength_nm", "red", "green", "blue", "combined"]
    else:
        assert columns == ["wavelength_nm", "qe"]


@pytest.mark.parametrize("sid", [s for s in SENSOR_IDS if s.endswith("c") and s != "icx285alm"])
def test_colour_combined_is_the_bayer_cell_mean(sid):
    t = qe_table(sid)
    np.testing.assert_allclose(t["combined"], (t["red"] + 2 * t["green"] + t["blue"]) / 4, atol=2e-6)


def test_imx178_qe_keeps_no_corrupt_near_infrared_tail():
    table = qe_table("imx178m")
    assert table["wavelength_nm"].max() <= 900.0
    assert table["qe"][table["wavelength_nm"] > 800].max() < 0.3


def test_lens_transmittance_is_a_fraction_and_flagged_as_placeholder():
    with open(CONFIGS / "lenses" / "cinegon-1.4-8mm.toml", "rb") as fh:
        lens = tomllib.load(fh)
    assert lens["name"] and lens["focal_length_mm"] == 8.0
    table = read_csv_columns(CONFIGS / "lenses" / lens["transmittance_csv"], ("wavelength_nm", "transmittance"), "lens")
    assert 0.0 < table["transmittance"].min() and table["transmittance"].max() <= 1.0
    assert "placeholder" in (CONFIGS / "lenses" / lens["transmittance_csv"]).read_text()


@pytest.mark.parametrize("name", ["paper-tank-led", "test-light"])
def test_light_profiles_have_one_spectrum_and_provenance(name):
    with open(CONFIGS / "lights" / f"{name}.toml", "rb") as fh:
        light = tomllib.load(fh)
    assert light["name"] and light["luminous_flux_lm"] > 0
    assert 0.0 < light["beam_half_angle_deg"] < 90.0
    assert ("spectrum" in light) != ("spectrum_csv" in light)
    assert all(light["provenance"].get(k) for k in ("luminous_flux_lm", "beam_half_angle_deg"))
    if "spectrum_csv" in light:
        table = read_csv_columns(CONFIGS / "lights" / light["spectrum_csv"], ("wavelength_nm", "relative"), "light")
        assert table["relative"].min() >= 0.0 and table["relative"].max() > 0.0


def test_paper_led_matches_the_paper():
    with open(CONFIGS / "lights" / "paper-tank-led.toml", "rb") as fh:
        light = tomllib.load(fh)
    assert (light["luminous_flux_lm"], light["beam_half_angle_deg"], light["spectrum"]) == (
        25000.0,
        40.0,
        "generic-led",
    )


def test_jerlov_table_is_complete_on_the_source_grid():
    table = jerlov()
    assert list(table.columns) == ["water_type", "wavelength_nm", "a_per_m", "b_per_m", "a_filled", "b_filled"]
    assert not table.isna().any().any()
    assert sorted(zip(table.water_type, table.wavelength_nm, strict=True)) == sorted(
        (t, w) for t in JERLOV_TYPES for w in JERLOV_NM
    )
    assert (table[["a_per_m", "b_per_m"]] > 0).all().all()


def test_jerlov_filled_flags_are_exactly_the_known_gaps():
    table = jerlov()
    assert table.a_filled.dtype == bool and table.b_filled.dtype == bool
    for column in ("a_filled", "b_filled"):
        flagged = {
            (t, int(w))
            for t, w in zip(table.water_type[table[column]], table.wavelength_nm[table[column]], strict=True)
        }
        assert flagged == KNOWN_GAPS


def test_jerlov_unfilled_cells_keep_source_values():
    table = jerlov().set_index(["water_type", "wavelength_nm"])
    assert table.loc[("9C", 700), ["a_per_m", "b_per_m"]].tolist() == [0.651, 2.07]
    assert table.loc[("3C", 650), ["a_per_m", "b_per_m"]].tolist() == [0.346, 0.8]
    assert table.loc[("5C", 575), ["a_per_m", "b_per_m"]].tolist() == [0.119, 1.23]


def test_beam_attenuation_increases_with_turbidity_at_550nm():
    c = jerlov().query("wavelength_nm == 550").set_index("water_type")
    c = c.a_per_m + c.b_per_m
    assert c["I"] < c["II"] < c["III"]
    assert c["1C"] < c["3C"] < c["5C"] < c["7C"] < c["9C"]


@pytest.mark.parametrize("nm", [600, 625, 650, 675, 700])
def test_filled_coastal_cells_lie_between_their_neighbour_types(nm):
    row = jerlov().query("wavelength_nm == @nm").set_index("water_type")
    c = row.a_per_m + row.b_per_m
    assert c["1C"] < c["3C"] < c["5C"] < c["7C"]
    assert row.a_per_m["1C"] <= row.a_per_m["5C"] <= row.a_per_m["7C"]
    assert row.b_per_m["3C"] < row.b_per_m["5C"] < row.b_per_m["7C"]


def test_pure_water_matches_pope_and_fry():
    table = read_csv_columns(CONFIGS / "water" / "pure_water_pope_fry_1997.csv", ("wavelength_nm", "a_per_m"), "w")
    assert table["wavelength_nm"][0] == 380.0 and table["wavelength_nm"][-1] == 727.5
    for nm, a in POPE_FRY.items():
        assert table["a_per_m"][table["wavelength_nm"] == nm].item() == a


def test_red_extension_covers_the_model_grid_and_agrees_with_pope_and_fry_in_the_overlap():
    pf = read_csv_columns(CONFIGS / "water" / "pure_water_pope_fry_1997.csv", ("wavelength_nm", "a_per_m"), "w")
    red = read_csv_columns(CONFIGS / "water" / "pure_water_red_extension.csv", ("wavelength_nm", "a_per_m"), "w")
    assert red["wavelength_nm"][0] <= 700.0 and red["wavelength_nm"][-1] >= 780.0
    overlap = red["wavelength_nm"] <= pf["wavelength_nm"][-1]
    assert overlap.sum() >= 3
    ratio = red["a_per_m"][overlap] / np.interp(red["wavelength_nm"][overlap], pf["wavelength_nm"], pf["a_per_m"])
    # the differences the header documents (+4.2 %, +1.5 %, −5.0 %): a transcription error shows here
    assert ratio == pytest.approx([1.0417, 1.0145, 0.9496], abs=5e-4)
    beyond = ~overlap
    assert np.all(red["a_per_m"][beyond] > pf["a_per_m"][-1])


def test_every_csv_has_a_provenance_header():
    for path in CONFIGS.rglob("*.csv"):
        assert path.read_text().startswith("# "), path


@pytest.mark.parametrize("folder", ["sensors", "lenses", "lights", "water"])
def test_index_lists_every_data_file(folder):
    index = (CONFIGS / "README.md").read_text()
    files = [p.relative_to(CONFIGS).as_posix() for p in (CONFIGS / folder).rglob("*") if p.is_file()]
    assert files and all(f"`{f}`" in index for f in files)
