"""Command-line interface ``battery-predictor``.

Each sub-command lives in its own module ``battery_predictor/cli/cmd_<name>.py``
exposing ``register(subparsers)``; that function adds its parser and sets
``func`` (callable taking the parsed ``argparse.Namespace`` and returning an exit
code). Errors derived from :class:`battery_predictor.errors.BatteryPredictorError`
are printed as one line on stderr with exit code 2, no traceback.
"""
