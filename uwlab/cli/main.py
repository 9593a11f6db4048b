"""The `uwlab` command: one parser, one subcommand module per verb, imported only when it is chosen.

`SUBCOMMANDS` is the table of verbs: name → (module, one-line help). ``uwlab --help`` and ``uwlab --version``
list it without importing any subcommand module (their imports — numpy, pandas, matplotlib, ... — would cost
seconds); the chosen verb's module is imported and its ``register(subparsers)`` adds the verb's parser, arguments
and ``func``. ``func(args)`` returns the exit code.

The error contract: `UwlabError` (bad input, a failed device) and `OSError` (a file the system refused) become one
line on stderr and exit code 2; Ctrl-C becomes one line ``interrupted`` and exit code 130; nothing below the CLI
prints. Ctrl-C is recognised by the SIGINT itself, not only by the KeyboardInterrupt it raises: a module interrupted
while it imports may turn the KeyboardInterrupt into another error (numpy raises ImportError). The command installs
its own SIGINT handler whatever disposition it inherits (a background job of a non-interactive shell starts with
SIGINT ignored, which would make Ctrl-C and `kill -INT` do nothing), and restores the inherited one on return.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
import threading
import typing

from uwlab import __version__
from uwlab.errors import UwlabError

SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "design": (
        "uwlab.cli.design",
        "predict FOV, exposure, framerate, DoF, response and SNR of a design; grids; inverse design",
    ),
    "explore": (
        "uwlab.cli.explore",
        "the design explorer: edit a design in a local web page, see its numbers and figures live, sweep, solve, save",
    ),
    "console": (
        "uwlab.cli.console",
        "the rig console: live image, histogram, clipping, focus aids, lights, spectrum and sweep runs in a web page",
    ),
    "devices": ("uwlab.cli.devices", "list cameras on every backend"),
    "grab": ("uwlab.cli.grab", "acquire frames from a camera and report statistics"),
    "light": ("uwlab.cli.light", "switch and dim the light, or calibrate it"),
    "spectrum": ("uwlab.cli.spectrum", "measure or import a spectrum and derive lux, W/m², photons, CCT"),
    "spectrometer": ("uwlab.cli.spectrometer", "calibrate an Ocean Insight spectrometer against a lamp file (.LMP)"),
    "sim": ("uwlab.cli.sim", "run simulated instruments until Ctrl-C; render simulated image sets"),
    "sweep": ("uwlab.cli.sweep", "run an exposure/aperture/gain/light-level/dark sweep plan"),
    "dataset": ("uwlab.cli.dataset", "inspect, check and repair sweep datasets"),
    "emva": ("uwlab.cli.emva", "EMVA 1288 characterisation of a camera or a fleet, datasheets, descriptor export"),
    "fit": ("uwlab.cli.fit", "calibrate the model against a dataset (emcee) and validate it"),
    "report": ("uwlab.cli.report", "write the HTML validation report of a directory"),
    "demo": ("uwlab.cli.demo", "run the paper's tank campaign on the simulated rig, fit, validate, report"),
    "port": ("uwlab.cli.port", "exact port optics and focusing aids; port calibration from images"),
    "mtf": ("uwlab.cli.mtf", "slanted-edge MTF (ISO 12233 e-SFR) of the edges in an image"),
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> typing.NoReturn:  # one line, exit 2, as for any bad input
        self.exit(2, f"{self.prog}: error: {message}\n")


def chosen_command(argv: list[str]) -> str | None:
    """The verb of a command line: its first word that is not an option (the top level has only flags)."""
    return next((word for word in argv if not word.startswith("-")), None)


def build_parser(chosen: str | None = None) -> argparse.ArgumentParser:
    """The parser with the full sub-parser of the verb `chosen`; the other verbs are listed with their help only,
    so that choosing one costs no imports of the others."""
    parser = _Parser(prog="uwlab", description="Design, calibrate and validate underwater camera systems.")
    parser.add_argument("--version", action="version", version=f"uwlab {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)
    for name, (module, help_text) in SUBCOMMANDS.items():
        if name == chosen:
            importlib.import_module(module).register(sub)
        else:
            sub.add_parser(name, help=help_text, add_help=False)
    return parser


def _interrupt_handled() -> None:
    """Tell the interpreter that the KeyboardInterrupt was handled.

    A KeyboardInterrupt raised inside exec() of a string (dataclasses and namedtuple build their methods that way,
    so Ctrl-C during an import can land there) leaves CPython's "unhandled KeyboardInterrupt" mark set although
    `main` caught it, and ``python -m uwlab.cli.main`` then ends by SIGINT (exit −2) instead of 130
    (``run_eval_code_obj`` in CPython 3.11's Python/pythonrun.c; Modules/main.c reads the mark). Every exec of a
    string clears the mark first."""
    exec("")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    chosen = chosen_command(argv)
    prefix = f"uwlab {chosen}" if chosen in SUBCOMMANDS else "uwlab"
    interrupts = []

    def on_sigint(signum, frame):
        interrupts.append(signum)
        raise KeyboardInterrupt

    # signals reach only the main thread's handlers (an embedding program calling main() elsewhere keeps its own)
    watch = threading.current_thread() is threading.main_thread()
    inherited = signal.getsignal(signal.SIGINT) if watch else None
    if watch:
        signal.signal(signal.SIGINT, on_sigint)
    try:
        args = build_parser(chosen).parse_args(argv)
        return int(args.func(args) or 0)
    except (KeyboardInterrupt, UwlabError, OSError, ImportError) as exc:
        if interrupts or isinstance(exc, KeyboardInterrupt):
            print(f"{prefix}: interrupted", file=sys.stderr)
            _interrupt_handled()
            return 130
        if isinstance(exc, BrokenPipeError):
            sys.stderr.close()
            return 0
        if isinstance(exc, ImportError):
            raise
        print(f"{prefix}: error: {exc}", file=sys.stderr)
        return 2
    finally:
        if watch:
            signal.signal(signal.SIGINT, inherited if inherited is not None else signal.default_int_handler)


if __name__ == "__main__":
    sys.exit(main())
