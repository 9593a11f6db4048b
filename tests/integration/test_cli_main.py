"""The `uwlab` dispatcher: the table of verbs, each module imported only when its verb is chosen."""

from __future__ import annotations

import subprocess
import sys

import pytest

from uwlab.cli.main import SUBCOMMANDS, build_parser, chosen_command, main

HEAVY = ("numpy", "pandas", "matplotlib", "scipy", "colour", "pyarrow", "emcee")


def test_help_and_version_import_no_subcommand_module():
    code = (
        "import sys\n"
        "from uwlab.cli.main import main\n"
        "for argv in (['--help'], ['--version']):\n"
        "    try:\n"
        "        main(argv)\n"
        "    except SystemExit as exc:\n"
        "        assert exc.code == 0, exc.code\n"
        f"print(sorted(m for m in sys.modules if m.split('.')[0] in {HEAVY!r} or m.startswith('uwlab.cli.')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "['uwlab.cli.main']"


def test_help_lists_every_verb_with_its_help(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    for name, (_, help_text) in SUBCOMMANDS.items():
        assert name in out and help_text.split()[0] in out


@pytest.mark.parametrize("name", SUBCOMMANDS)
def test_every_verb_registers_its_own_parser(name, capsys):
    parser = build_parser(name)
    with pytest.raises(SystemExit) as exit_info:
        parser.parse_args([name, "--help"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: uwlab {name}")


def test_the_verb_is_the_first_word_that_is_not_an_option():
    assert chosen_command(["--version"]) is None
    assert chosen_command(["-h", "fit", "--out", "x"]) == "fit"


def test_unknown_verb_is_one_line_and_exit_2(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["desing"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'desing'" in err


def test_an_interrupt_inside_exec_still_exits_130_under_python_m(tmp_path):
    """Ctrl-C can land inside exec() of a string (a dataclass being built while a verb imports its modules). CPython
    then marks the KeyboardInterrupt unhandled even though `main` handled it, and `python -m` ended the process by
    SIGINT (-2). Here the verb's work is such an exec."""
    (tmp_path / "interrupted_in_exec.py").write_text(
        "import argparse, sys\n"
        "from uwlab.cli import main as cli\n"
        "class Parser:\n"
        "    def parse_args(self, argv):\n"
        "        return argparse.Namespace(func=lambda args: exec('raise KeyboardInterrupt'))\n"
        "cli.build_parser = lambda chosen: Parser()\n"
        "sys.exit(cli.main(['design']))\n"
    )
    done = subprocess.run(
        [sys.executable, "-m", "interrupted_in_exec"], cwd=tmp_path, capture_output=True, text=True, timeout=60
    )
    assert (done.returncode, done.stderr) == (130, "uwlab design: interrupted\n")
