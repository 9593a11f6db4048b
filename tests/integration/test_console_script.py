"""The installed command as a process: bad input is one line on stderr and exit code 2, no traceback."""

from tests.support.cli_process import run
from tests.support.paths import EXAMPLE


def test_console_script_exit_code_without_traceback(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(EXAMPLE.read_text().replace("f_number = 2.0", "f_number = -1"))
    code, _, err = run("design", bad)
    assert code == 2
    assert err.strip().splitlines() == [err.strip()] and "lens.f_number" in err
