"""The ``uwlab`` command in process (`uwlab.cli.main.main`), for the tests whose point is not a process boundary or a
signal (those use `tests.support.cli_process`)."""

from __future__ import annotations

from uwlab.cli.main import main


def one_line_error(capsys, argv: list[str]) -> str:
    """``uwlab ARGV`` refused: exit code 2, nothing on stdout, one line on stderr and no traceback; returns the line."""
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1 and "Traceback" not in captured.err, captured.err
    return captured.err
