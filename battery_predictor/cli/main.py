"""Entry point of the ``battery-predictor`` command."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings

from battery_predictor.errors import BatteryPredictorError

#: Sub-command modules, each with ``register(subparsers)``.
COMMAND_MODULES = (
    "battery_predictor.cli.cmd_screen",
    "battery_predictor.cli.cmd_fit",
    "battery_predictor.cli.cmd_simulate",
    "battery_predictor.cli.cmd_profile",
    "battery_predictor.cli.cmd_bag",
    "battery_predictor.cli.cmd_lab",
    "battery_predictor.cli.cmd_run",
    "battery_predictor.cli.cmd_replay",
    "battery_predictor.cli.cmd_evaluate",
    "battery_predictor.cli.cmd_diagnose",
    "battery_predictor.cli.cmd_demo",
)


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser with every available sub-command."""
    parser = argparse.ArgumentParser(prog="battery-predictor", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:
                continue  # sub-command not implemented in this build
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the process exit code."""
    os.environ.setdefault("TQDM_DISABLE", "0")
    warnings.filterwarnings("ignore", category=DeprecationWarning)
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except BatteryPredictorError as exc:
        print(f"battery-predictor: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("battery-predictor: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into e.g. `head`: not an error of ours
        try:
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - silence the interpreter's flush at exit
        except OSError:
            pass
        return 0


if __name__ == "__main__":
    sys.exit(main())
