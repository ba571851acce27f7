"""Entry point of the ``sustain-drake`` command.

Each sub-command lives in its own module with ``register(subparsers)``; the module's handler
returns the process exit code. ``CliError`` (raised by handlers for bad input) is printed as one
line on stderr with exit code 2, never as a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from sustain_drake.cli.common import EXIT_BAD_INPUT, CliError

# Modules of this package that register sub-commands, in the order ``--help`` lists them.
COMMAND_MODULES = (
    "sustain_drake.cli.calibrate",
    "sustain_drake.cli.demo",
    "sustain_drake.cli.simulate",
    "sustain_drake.cli.sweep",
    "sustain_drake.cli.graph",
)

def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sustain-drake",
        description="Sustainable hand-eye and payload coordination on Drake.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args))
    except CliError as e:
        print(f"sustain-drake: error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("sustain-drake: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader of the output closed it (e.g. ``| head``): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no error at the final flush
        return 141  # 128 + SIGPIPE, as a shell reports it


if __name__ == "__main__":
    sys.exit(main())
