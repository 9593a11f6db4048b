"""The `uwlab` command: one parser, one subcommand module per verb.

Each module in `uwlab.cli` that defines ``register(subparsers)`` adds its subcommand and sets
``func`` on its parser; ``func(args)`` returns the exit code. `UwlabError` becomes one line on
stderr and exit code 2; nothing below the CLI prints.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from uwlab import __version__
from uwlab.errors import UwlabError

SUBCOMMAND_MODULES = ("design", "explore", "devices", "grab", "light", "spectrum", "sim", "sweep", "dataset", "emva",
                      "fit", "report", "demo", "port")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2, as for any bad input
        self.exit(2, f"uwlab: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="uwlab", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"uwlab {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name in SUBCOMMAND_MODULES:
        importlib.import_module(f"uwlab.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except UwlabError as exc:
        print(f"uwlab {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print(f"uwlab {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
