"""Progress fits the place: a bar on a terminal, nothing in a file or pipe, tqdm.auto in a Jupyter kernel."""

import io
import sys
import types

import uwlab.progress as progress


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_nothing_is_written_when_the_stream_is_not_a_terminal():
    stream = io.StringIO()
    with progress.bar(total=5, desc="sweep", unit="point", stream=stream) as shown:
        for _ in range(5):
            shown.update()
        shown.set_postfix_str("latest")
    assert stream.getvalue() == "" and shown.n == 5 and shown.place == "off"


def test_a_terminal_gets_a_bar():
    stream = Terminal()
    with progress.bar(total=4, desc="sweep", unit="point", stream=stream, leave=True) as shown:
        shown.update(4)
    assert shown.place == "terminal" and "sweep" in stream.getvalue() and "4/4" in stream.getvalue()


def test_nothing_is_drawn_before_the_first_update():
    stream = Terminal()
    with progress.bar(total=4, desc="sweep", stream=stream):
        pass
    assert stream.getvalue() == ""


def test_a_jupyter_kernel_is_recognised(monkeypatch):
    shell = types.SimpleNamespace(config={"IPKernelApp": {}})
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: shell))
    assert progress.where(io.StringIO()) == "notebook"
    shell.config = {}  # a terminal IPython is not a notebook
    assert progress.where(io.StringIO()) == "off"


def test_the_tau_bar_counts_autocorrelation_times():
    stream = Terminal()
    shown, update = progress.tau_bar("sampling", stream=stream)
    update(1000, 12.5)
    update(2000, 80.0)  # past the target: capped
    shown.close()
    assert shown.n == progress.TAU_TARGET and "2000 steps" in stream.getvalue()


def test_the_cli_modules_use_the_one_helper():
    """No progress display outside uwlab.progress (grep: only it imports tqdm)."""
    from pathlib import Path

    root = Path(progress.__file__).parent
    users = sorted(
        str(p.relative_to(root)) for p in root.rglob("*.py") if "tqdm" in p.read_text() and p.name != "progress.py"
    )
    assert users in ([], ["cli/light.py", "cli/sweep.py"])  # the last two: owned by other branches (lead merges)
