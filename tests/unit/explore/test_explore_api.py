"""The explorer's JSON API (Starlette TestClient over httpx2): `/api/design` is `uwlab design --json`, bad input is
the CLI's one line with 422, the page's view reads like the CLI's table, saved TOML reads back to the same
numbers, sweeps and solve agree with the CLI, the form follows the config schema, user profiles load."""

import json
import shutil
import tomllib
from pathlib import Path

import numpy as np
import plotly.graph_objects as go
import pytest
from starlette.testclient import TestClient

from uwlab.cli.main import main
from uwlab.sim.devices.camera import SimTruth
from uwlab.experiments.emva.simulate import simulate_photon_transfer
from uwlab.explore.app import create_app
from uwlab.explore.catalog import Catalog
from uwlab.explore.forms import form
from uwlab.explore.inputs import field_texts, load_served, value_text
from uwlab.model.config import DesignConfig, parse_value
from uwlab.model.data import config_dir
from uwlab.model.build import load_design
from uwlab.model.evaluation import stage_spectra
from uwlab.model.sensor import load_sensor_profile

from tests.support.paths import EXAMPLE


@pytest.fixture(scope="module")
def client():
    with TestClient(create_app(load_served(EXAMPLE), Catalog()), base_url="http://127.0.0.1") as c:
        yield c


def cli(capsys, *argv) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def cli_json(capsys, *argv) -> dict:
    code, out, err = cli(capsys, *argv)
    assert code == 0, err
    return json.loads(out)


def sets(overrides: dict) -> list[str]:
    return [arg for key, value in overrides.items() for arg in ("--set", f"{key}={value_text(value)}")]


@pytest.mark.parametrize(
    "overrides",
    [
        {},
        {"lens.f_number": 4, "light.luminous_flux_lm": 30000},
        {"operation.exposure_s": "max-blur", "water.type": "jerlov-3C", "target.reflectance": "sand"},
        {"housing.port": "dome", "housing.dome_radius_mm": 50, "housing.dome_thickness_mm": 5, "sensor.gain_db": 12.5},
    ],
)
def test_api_design_is_the_cli_json(client, capsys, overrides):
    response = client.post("/api/design", json={"set": overrides})
    assert response.status_code == 200
    assert response.json() == cli_json(capsys, "design", str(EXAMPLE), *sets(overrides), "--json")


@pytest.mark.parametrize(
    "overrides",
    [
        {"lens.f_number": 0},
        {"lens.f_number": "2"},
        {"camera.zoom": 2},
        {"water.type": "jerlov-X"},
        {"operation.overlap": 1.0},
        {"sensor.profile": "imx999"},
        {"housing.port": "dome"},
        {"lens": 3},
    ],
)
def test_bad_input_is_422_with_the_cli_line(client, capsys, overrides):
    response = client.post("/api/design", json={"set": overrides})
    code, out, err = cli(capsys, "design", str(EXAMPLE), *sets(overrides), "--json")
    assert code == 2 and out == ""
    assert response.status_code == 422
    assert f"uwlab design: error: {response.json()['error']}\n" == err
    assert response.json()["key"] in err


@pytest.mark.parametrize(
    "body, words",
    [
        ("{not json", "must be JSON"),
        ("[1, 2]", "must be a JSON object"),
        ('{"sett": {}}', "unknown member"),
        ('{"set": [1]}', "must be an object"),
        ('{"text": {"lens.f_number": 4}}', "text values must be strings"),
    ],
)
def test_malformed_requests_are_one_line(client, body, words):
    response = client.post("/api/design", content=body, headers={"Content-Type": "application/json"})
    assert response.status_code == 422
    assert words in response.json()["error"] and "\n" not in response.json()["error"]


def test_text_values_are_parsed_as_the_cli_parses_set(client):
    served = load_served(EXAMPLE)
    texts = field_texts(served.raw)
    assert all(
        parse_value(text) == value
        for text, value in zip(texts.values(), [v for body in served.raw.values() for v in body.values()], strict=True)
    )
    from_texts = client.post("/api/design", json={"config": {}, "text": texts}).json()
    assert from_texts == client.post("/api/design", json={}).json()
    typed = client.post("/api/design", json={"text": {"lens.f_number": "4", "operation.exposure_s": "max-blur"}})
    assert (
        typed.json()
        == client.post("/api/design", json={"set": {"lens.f_number": 4, "operation.exposure_s": "max-blur"}}).json()
    )
    unset = client.post("/api/design", json={"text": {"operation.min_dof_m": ""}}).json()
    assert unset["min_f_number_for_dof"] is None


def test_view_reads_like_the_cli_table(client, capsys):
    overrides = {"operation.exposure_s": "max-blur"}
    view = client.post("/api/view", json={"set": overrides}).json()
    code, text, _ = cli(capsys, "design", str(EXAMPLE), *sets(overrides))
    assert code == 0
    lines = text.splitlines()
    for row in view["rows"]:
        line = f"{row['label']:<32} {row['text']} {row['unit']}".rstrip()
        assert any(candidate.startswith(line) for candidate in lines), line
    snr_db = next(r for r in view["rows"] if r["key"] == "snr_db")
    assert (snr_db["text"], snr_db["unit"]) == ("36.5", "dB")  # the README's worked example
    assert f"  {view['budget']['rows'][0]['label']:<30} {view['budget']['rows'][0]['text']}" in text
    assert view["result"] == cli_json(capsys, "design", str(EXAMPLE), *sets(overrides), "--json")


def test_warnings_sit_beside_the_number_that_causes_them(client):
    def warnings(overrides):
        view = client.post("/api/view", json={"set": overrides}).json()
        return {w["kind"]: w for w in view["warnings"]}, view["result"]

    found, result = warnings({})  # the example: 0.2 ms exposure, 0.3 m DoF required at F2
    assert set(found) == {"blur", "dof"}
    assert found["blur"]["outputs"] == ["exposure_s"] and found["dof"]["outputs"] == ["dof_m"]
    limit = result["max_exposure_s"]
    double, _ = warnings({"operation.exposure_s": 2 * limit})  # blur grows linearly: 2 × the limit is 2 px
    assert "motion blur 2 px > limit 1 px" in double["blur"]["message"]
    fixed, _ = warnings({"operation.exposure_s": "max-blur", "lens.f_number": 32})
    assert "blur" not in fixed and "dof" not in fixed
    saturated, result = warnings({"sensor.gain_db": 30})
    assert result["saturated"] and saturated["saturated"]["outputs"][0] == "mean_dn"


def test_figures_are_valid_plotly_and_show_the_model(client):
    view = client.post("/api/view", json={"set": {"lens.f_number": 5.6}}).json()
    assert set(view["figures"]) == {"dof", "spectra", "operation", "water", "qe", "budget"}
    for figure in view["figures"].values():
        go.Figure(figure)  # raises on anything Plotly does not know
    design = load_design(EXAMPLE, {"lens.f_number": 5.6})
    spectra = stage_spectra(design)
    source = view["figures"]["spectra"]["data"][0]
    assert source["y"] == pytest.approx(spectra["source_w_nm"].tolist())
    marker = next(t for t in view["figures"]["dof"]["data"] if t.get("mode") == "markers")
    assert (marker["x"], marker["y"]) == ([5.6], [1.0])
    budget = view["figures"]["budget"]["data"][0]
    assert sorted(budget["x"]) == sorted(view["result"]["light_budget_stops"].values())


def test_sweep_values_are_single_designs(client):
    answer = client.post(
        "/api/sweep",
        json={"grid": {"lens.f_number": "2:8:2", "water.type": "jerlov-I,jerlov-9C"}, "output": "dof_m.near"},
    ).json()
    assert answer["axes"] == {"lens.f_number": [2.0, 4.0, 6.0, 8.0], "water.type": ["jerlov-I", "jerlov-9C"]}
    assert np.shape(answer["values"]) == (4, 2) and answer["points"] == 8
    for i, n in enumerate(answer["axes"]["lens.f_number"]):
        for j, water in enumerate(answer["axes"]["water.type"]):
            single = client.post("/api/design", json={"set": {"lens.f_number": n, "water.type": water}}).json()
            assert answer["values"][i][j] == pytest.approx(single["dof_m"]["near"], rel=1e-12)
    line = client.post("/api/sweep", json={"grid": {"operation.altitude_m": [1, 2]}, "output": "snr_db"}).json()
    for h, value in zip([1, 2], line["values"], strict=True):
        assert value == pytest.approx(
            client.post("/api/design", json={"set": {"operation.altitude_m": h}}).json()["snr_db"], rel=1e-6
        )
    go.Figure(answer["figure"])


@pytest.mark.parametrize(
    "body, key",
    [
        ({"grid": {"lens.f_number": "8:2:1"}, "output": "snr_db"}, "lens.f_number"),
        ({"grid": {"lens.f_number": "1:4:1"}, "output": "nope"}, "output"),
        ({"grid": {}, "output": "snr_db"}, "grid"),
        ({"grid": {"lens.f_number": "1:1000:0.001"}, "output": "snr_db"}, "grid"),
        ({"grid": {"lens.f_number": "0,2"}, "output": "snr_db"}, "lens.f_number"),
    ],
)
def test_bad_sweeps_are_one_line(client, body, key):
    response = client.post("/api/sweep", json=body)
    assert response.status_code == 422 and response.json()["key"] == key


def test_solve_is_the_cli_solve(client, capsys):
    free, require = ["light.luminous_flux_lm=1000:100000"], ["snr_db >= 30", "mean_fraction <= 0.6"]
    response = client.post(
        "/api/solve",
        json={
            "set": {"operation.exposure_s": "max-blur"},
            "free": free,
            "require": require,
            "objectives": [{"minimize": "light.luminous_flux_lm"}],
        },
    )
    expected = cli_json(
        capsys,
        "design",
        "solve",
        str(EXAMPLE),
        "--set",
        "operation.exposure_s=max-blur",
        "--free",
        free[0],
        "--require",
        require[0],
        "--require",
        require[1],
        "--minimize",
        "light.luminous_flux_lm",
        "--json",
    )
    assert response.status_code == 200 and response.json()["answer"] == expected
    bad = client.post("/api/solve", json={"free": free, "require": ["snr >= x"], "objectives": []})
    assert bad.status_code == 422 and bad.json()["key"] == "--require"


def test_saved_toml_reads_back_to_the_same_numbers(client, capsys, tmp_path):
    lights, lenses = config_dir() / "lights", config_dir() / "lenses"
    body = {
        "config": {},
        "text": {
            **field_texts(load_served(EXAMPLE).raw),
            "light.spectrum": str(lights / "test-light_spectrum.csv"),
            "lens.transmittance": str(lenses / "cinegon-1.4-8mm_transmittance.csv"),
            "lens.f_number": "2.8000000000000003",
            "operation.exposure_s": "0.000123456789",
        },
    }
    response = client.post("/api/toml", json=body)
    assert response.status_code == 200 and "attachment" in response.headers["content-disposition"]
    saved = tmp_path / "elsewhere" / "design.toml"
    saved.parent.mkdir()
    saved.write_text(response.text)
    assert tomllib.loads(response.text)["lens"]["f_number"] == 2.8000000000000003
    expected = client.post("/api/design", json=body).json()
    assert cli_json(capsys, "design", str(saved), "--json") == expected  # bit for bit
    loaded = client.post("/api/load", json={"toml": response.text, "name": "design.toml"}).json()
    assert client.post("/api/design", json={"config": {}, "text": loaded["text"]}).json() == expected


def test_served_relative_files_are_saved_absolute(tmp_path, capsys):
    folder = tmp_path / "project"
    folder.mkdir()
    shutil.copy(config_dir() / "lights" / "test-light_spectrum.csv", folder / "led.csv")
    config = folder / "design.toml"
    config.write_text(EXAMPLE.read_text().replace('spectrum = "generic-led"', 'spectrum = "led.csv"'))
    with TestClient(create_app(load_served(config)), base_url="http://127.0.0.1") as c:
        text = c.post("/api/toml", json={}).text
        expected = c.post("/api/design", json={}).json()
    assert tomllib.loads(text)["light"]["spectrum"] == str(folder / "led.csv")
    (tmp_path / "saved.toml").write_text(text)
    assert cli_json(capsys, "design", str(tmp_path / "saved.toml"), "--json") == expected


def test_load_refuses_what_uwlab_design_refuses(client):
    bad = client.post("/api/load", json={"toml": "[lens\nf_number = 2", "name": "broken.toml"})
    assert bad.status_code == 422 and "broken.toml" in bad.json()["error"]
    wrong = EXAMPLE.read_text().replace("f_number = 2.0", "f_number = 0.02")
    refused = client.post("/api/load", json={"toml": wrong, "name": "wrong.toml"})
    assert refused.status_code == 422 and refused.json()["key"] == "lens.f_number"


def test_form_has_every_key_of_the_schema_with_its_unit(client):
    page = client.get("/").text
    sections = {s.name: s for s in form()}
    tables = {
        name: field for name, field in DesignConfig.model_fields.items() if hasattr(field.annotation, "model_fields")
    }
    assert list(sections) == list(tables) and "lights" not in sections  # [[lights]], an array, is edited in the TOML
    for name, field in tables.items():
        model = field.annotation
        assert [f.name for f in sections[name].fields] == list(model.model_fields), name
        for key in model.model_fields:
            assert f'data-key="{name}.{key}"' in page
    units = {f.key: f.unit for s in form() for f in s.fields}
    assert units["light.luminous_flux_lm"] == "lm" and units["operation.exposure_s"] == "s"
    assert units["sensor.gain_db"] == "dB" and units["housing.dome_radius_mm"] == "mm"
    exposure = next(f for f in sections["operation"].fields if f.name == "exposure_s")
    assert exposure.words == ("max-blur",) and exposure.number.lo == 1e-6 and exposure.grid


def test_a_key_added_to_the_schema_appears_in_the_form():
    from pydantic import Field

    from uwlab.model.config import Lens, _section
    from uwlab.model.schema import FocalLengthMm, Grid

    class ZoomLens(Lens):
        """The lens, with a zoom."""

        zoom_max_mm: Grid[FocalLengthMm] | None = Field(None, description="longest focal length of a zoom [mm]")

    class ZoomConfig(DesignConfig):
        lens: ZoomLens = _section(ZoomLens)

    lens = next(s for s in form(ZoomConfig) if s.name == "lens")
    zoom = lens.fields[-1]
    assert (zoom.key, zoom.unit, zoom.grid, zoom.required) == ("lens.zoom_max_mm", "mm", True, False)
    assert (zoom.number.lo, zoom.number.hi) == (1.0, 2000.0) and "longest focal length" in zoom.description


def test_plotly_is_served_from_the_installed_package(client):
    import plotly

    response = client.get("/static/plotly.min.js")
    assert response.status_code == 200
    assert response.content == (Path(plotly.__file__).parent / "package_data" / "plotly.min.js").read_bytes()
    page = client.get("/").text
    assert '<script src="/static/plotly.min.js">' in page and "https://" not in page


def test_presets_are_the_shipped_components(client):
    presets = client.get("/api/schema").json()["presets"]
    sensors = [p["text"]["sensor.profile"] for p in presets["sensor"]]
    assert sensors == sorted(p.stem for p in (config_dir() / "sensors").glob("*.toml"))
    led = next(p for p in presets["light"] if p["label"].startswith("Paper tank LED"))
    assert led["text"] == {
        "light.luminous_flux_lm": "25000.0",
        "light.beam_half_angle_deg": "40.0",
        "light.beam_half_angle_in_air_deg": "",
        "light.spectrum": "generic-led",
    }
    test_light = next(p for p in presets["light"] if p["label"].startswith("Test Light"))
    view = client.post("/api/design", json={"text": test_light["text"]})
    assert view.status_code == 200  # its spectrum CSV is found wherever the design is


@pytest.fixture(scope="module")
def emva_profile(tmp_path_factory):
    """A sensor profile written by `uwlab emva characterize` from a simulated photon transfer."""
    truth = SimTruth.from_sensor_profile(load_sensor_profile("imx250m"), resolution_px=(64, 64))
    root = tmp_path_factory.mktemp("explore_emva")
    simulate_photon_transfer(
        root / "ds",
        truth,
        rate_e_per_s=1.07e5,
        quantum_efficiency=0.6,
        exposures_us=np.linspace(3e3, 120e3, 24),
        frames=2,
        seed=5,
    )
    assert main(["emva", "characterize", str(root / "ds"), "--out", str(root / "out"), "--name", "mycam"]) == 0
    return root / "out" / "mycam.toml"


def test_an_emva_profile_can_be_loaded(emva_profile, capsys):
    served = load_served(EXAMPLE).with_roots(emva_profile.parent)  # as `uwlab explore --data-dir OUT`
    with TestClient(create_app(served, Catalog()), base_url="http://127.0.0.1") as c:
        added = c.post("/api/profile", json={"path": str(emva_profile)}).json()
        assert added["section"] == "sensor" and added["text"] == {"sensor.profile": str(emva_profile)}
        assert any(p["user"] and p["text"] == added["text"] for p in added["presets"]["sensor"])
        result = c.post("/api/design", json={"text": added["text"]}).json()
        refused = c.post("/api/profile", json={"path": str(EXAMPLE)})
    assert result == cli_json(capsys, "design", str(EXAMPLE), "--set", f"sensor.profile='{emva_profile}'", "--json")
    profile = load_sensor_profile(str(emva_profile))
    assert result["mean_dn"] == pytest.approx(profile.K_dn_per_e * result["mean_electrons"] + profile.dark_offset_dn)
    assert refused.status_code == 422 and "not a sensor, light or lens profile" in refused.json()["error"]
