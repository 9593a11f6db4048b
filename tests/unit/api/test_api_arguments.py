"""The Python API takes what the CLI takes: its errors name the Python argument (``out``), not the option
(``--out``); plans and configs given by name are the bundled ones from any folder; every option of the CLI verbs has
an argument of the same meaning and the same default (one place decides it)."""

import argparse
import inspect

import pytest

import uwlab
from uwlab.cli.main import build_parser
from uwlab.errors import ConfigError


def test_sweep_refuses_a_missing_parent_naming_out_not_the_flag(tmp_path):
    """The rule of `uwlab.outputs` (the parent of a new dataset must exist), before any device starts."""
    target = tmp_path / "missing" / "tank"
    with pytest.raises(ConfigError) as info:
        uwlab.sweep("plans/tank-exposure-sweep.toml", target, sim=True, progress=False)
    assert str(info.value) == f"out = '{target}': directory {target.parent} does not exist"
    assert not target.parent.exists()


def test_resume_without_a_dataset_and_an_existing_one_speak_python(tmp_path):
    with pytest.raises(ConfigError) as info:
        uwlab.sweep("plans/tank-exposure-sweep.toml", None, resume=True, progress=False)
    assert str(info.value).startswith("out = None:")
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError) as info:
        uwlab.fit(tmp_path / "no-dataset", out=tmp_path / "file" / "fit", progress=False)
    assert "--" not in str(info.value)


def test_report_names_out(tmp_path):
    with pytest.raises(ConfigError) as info:
        uwlab.report(tmp_path, out=tmp_path / "nonexistent" / "r.html")
    assert str(info.value).startswith("out = ") and "does not exist" in str(info.value)


def test_plans_and_designs_by_name_from_any_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert uwlab.load_plan("plans/tank-exposure-sweep.toml").name == "tank-exposure-sweep"
    assert uwlab.load_design("design/example.toml").sensor.name == "IMX250M"
    with pytest.raises(ConfigError, match=r"^plan = 'plans/nonesuch.toml': no such file here or under "):
        uwlab.load_plan("plans/nonesuch.toml")


def test_a_file_of_the_working_directory_wins_over_the_bundled_one(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "design").mkdir()
    bundled = uwlab.config_path("design/example.toml").read_text()
    (tmp_path / "design" / "example.toml").write_text(bundled.replace("altitude_m = ", "altitude_m = 2.5 #", 1))
    assert uwlab.load_design("design/example.toml")["operation.altitude_m"] == 2.5


# CLI verb → (the API function, {option dest: argument}, {CLI-only dest: why it has no argument})
VERBS = {
    "fit": (
        uwlab.fit,
        {
            "dataset": "dataset",
            "config": "config",
            "out": "out",
            "train": "train",
            "model": "model",
            "sensor": "sensor",
            "channel": "channel",
            "held_out": "held_out",
            "dask": "dask",
        },
        {"json": "output format"},
    ),
    "sweep": (
        uwlab.sweep,
        {"plan": "plan", "sim": "sim", "out": "out", "force": "force"},
        {
            "json": "output format",
            "resume": "resume=True with out=DIR",
            "non_interactive": "confirm=None (a callable, not a prompt)",
        },
    ),
    "report": (uwlab.report, {"dir": "source", "out": "out", "force": "force"}, {"json": "output format"}),
    "grab": (
        uwlab.grab,
        {
            "backend": "backend",
            "device": "device_id",
            "cti": "cti",
            "fake": "fake",
            "config": "config",
            "sensor": "sensor",
            "exposure_us": "exposure_us",
            "gain_db": "gain_db",
            "pixel_format": "pixel_format",
            "bayer": "bayer",
            "frames": "frames",
            "roi": "roi",
            "timeout_s": "timeout_s",
            "save": "save",
        },
        {"json": "output format"},
    ),
}


def _options(verb: str) -> dict[str, argparse.Action]:
    parser = build_parser(verb)
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[verb]
    return {a.dest: a for a in sub._actions if a.dest != "help"}


@pytest.mark.parametrize("verb", sorted(VERBS))
def test_every_cli_option_has_an_argument_with_the_same_default(verb):
    function, arguments, cli_only = VERBS[verb]
    parameters = inspect.signature(function).parameters
    options = _options(verb)
    assert set(options) == set(arguments) | set(cli_only), "a CLI option without its Python argument"
    for dest, name in arguments.items():
        default = parameters[name].default
        if options[dest].option_strings:  # a positional is required in both
            cli_default = options[dest].default
            # an appended option's empty list is the argument's None ("none given")
            assert default == cli_default or (cli_default == [] and default is None), (verb, dest)
