"""Entry point of the ``battery-predictor`` command."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings

from battery_predictor.errors import BatteryPredictorError, cli_flags

#: Sub-command modules, each with ``register(subparsers)``.
COMMAND_MODULES = (
    "battery_predictor.cli.cmd_screen",
    "battery_predictor.cli.cmd_fit",
    "battery_predictor.cli.cmd_fleet",
    "battery_predictor.cli.cmd_ocv",
    "battery_predictor.cli.cmd_simulate",
    "battery_predictor.cli.cmd_profile",
    "battery_predictor.cli.cmd_bag",
    "battery_predictor.cli.cmd_lab",
    "battery_predictor.cli.cmd_run",
    "battery_predictor.cli.cmd_replay",
    "battery_predictor.cli.cmd_evaluate",
    "battery_predictor.cli.cmd_evaluate_runtime",
    "battery_predictor.cli.cmd_diagnose",
    "battery_predictor.cli.cmd_demo",
)


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser with every available sub-command."""
    parser = argparse.ArgumentParser(prog="battery-predictor", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    _record_flags(parser)
    return parser


def flag_map(parser: argparse.ArgumentParser) -> dict[str, dict[object, str]]:
    """The parser's flags per Python option name and value, for the hints of :func:`errors.option_hint`.

    ``--drop-nan`` (store_true, dest ``drop_nan``) gives ``{"drop_nan": {True: "--drop-nan"}}``; a flag
    with choices gives one entry per choice; any other flag taking a value gives ``{None: "--flag VALUE"}``.
    """
    out: dict[str, dict[object, str]] = {}
    for action in parser._actions:  # argparse has no public accessor
        if not action.option_strings or action.dest in ("help", argparse.SUPPRESS):
            continue
        flag = max(action.option_strings, key=len)
        entry = out.setdefault(action.dest, {})
        if isinstance(action, argparse._StoreConstAction):  # store_true / store_false
            entry[action.const] = flag
        elif action.choices:
            entry.update({choice: f"{flag} {choice}" for choice in action.choices})
        else:
            entry[None] = f"{flag} {action.metavar or action.dest.upper()}"
    return out


def _record_flags(parser: argparse.ArgumentParser) -> None:
    """Give every command's parser a ``cli_flags`` default: its own :func:`flag_map`."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                sub.set_defaults(cli_flags=flag_map(sub))
                _record_flags(sub)


def one_line_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                     line: str | None = None) -> str:
    """A warning as the command line shows it: one line, no source file or code line."""
    return f"battery-predictor: warning: {message}\n"


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the process exit code."""
    os.environ.setdefault("TQDM_DISABLE", "0")
    warnings.filterwarnings("ignore", category=DeprecationWarning)
    parser = build_parser()
    args = parser.parse_args(argv)
    shown_as = warnings.formatwarning
    warnings.formatwarning = one_line_warning
    try:
        with cli_flags(getattr(args, "cli_flags", {})):
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
    finally:
        warnings.formatwarning = shown_as


if __name__ == "__main__":
    sys.exit(main())
