"""Helpers shared by the sub-commands (loading data, JSON output)."""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from battery_predictor.errors import InputDataError
from battery_predictor.params import PackParams
from battery_predictor.recording import DeepestState, Recording

if TYPE_CHECKING:
    import argparse
    from contextlib import AbstractContextManager

    from battery_predictor.fitting.data_limits import FitDataLimits
    from battery_predictor.replay.stream import ReplayStream
    from battery_predictor.simulation.base import PackSimResult


def load_data(paths: Sequence[str], *, trim: bool = True, duplicate_times: str = "error", drop_nan: bool = False,
              expect_discharge: bool = True, pack: PackParams | None = None) -> list[Recording]:
    """Load recordings (CSV or bag); trimmed to their discharge unless ``trim`` is False.

    With ``pack``, each recording's voltage must be plausible for that pack
    (:func:`battery_predictor.params_checks.check_recordings_against_pack`).
    """
    from battery_predictor.fitting.problem import trim_to_discharge
    from battery_predictor.io.loader import load_recording
    from battery_predictor.params_checks import check_recordings_against_pack

    recs = [load_recording(p, duplicate_times=duplicate_times, drop_nan=drop_nan,
                           expect_discharge=None if expect_discharge else False) for p in paths]
    if pack is not None:
        check_recordings_against_pack(pack, recs)
    return [trim_to_discharge(r) for r in recs] if trim else recs


def _clean(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


def engine_fallback(results: Iterable[PackSimResult]) -> str | None:
    """Why the engine handed simulations to another simulator (``extra["engine_fallback"]``), None when it did not."""
    reasons = sorted({res.extra["engine_fallback"] for res in results if res.extra.get("engine_fallback")})
    return "; ".join(reasons) if reasons else None


def print_json(obj: dict[str, Any]) -> None:
    """Print exactly one JSON object on stdout (non-finite numbers become null)."""
    sys.stdout.write(json.dumps(_clean(obj), sort_keys=False) + "\n")
    sys.stdout.flush()


def add_input_check_arguments(parser: argparse.ArgumentParser) -> None:
    """``--duplicate-times``, ``--drop-nan`` and ``--no-sign-check``: the ways out of the input checks."""
    # cycler exports repeat the time at step changes (the later row starts the new step; the LG M50 and
    # Panasonic files of ../shared/data do): the last row of each repeated time is kept by default, as
    # diagnose always did; 'error' refuses them. Time going backwards is refused whatever the choice.
    parser.add_argument("--duplicate-times", choices=("error", "keep_first", "keep_last"), default="keep_last",
                        help="CSV rows that repeat a timestamp: keep the last row of each (default: the later row "
                             "starts the new step), keep the first, or reject ('error')")
    parser.add_argument("--drop-nan", action="store_true",
                        help="drop rows with an empty/NaN time, voltage or current (fill temperature gaps)")
    parser.add_argument("--no-sign-check", dest="expect_discharge", action="store_false",
                        help="skip the current-sign check (current_A > 0 = discharge)")


def data_options(args: argparse.Namespace) -> dict[str, Any]:
    """The :func:`load_data` options of a command that used :func:`add_data_arguments`."""
    return {"trim": not args.no_trim, "duplicate_times": args.duplicate_times, "drop_nan": args.drop_nan,
            "expect_discharge": args.expect_discharge}


def add_resample_arguments(parser: argparse.ArgumentParser, command: str) -> None:
    """``--resample SECONDS`` and ``--no-resample`` of ``fit`` and ``simulate`` (see :func:`prepared_data`)."""
    parser.add_argument("--resample", type=float, default=None, metavar="SECONDS",
                        help="average the data over windows of this many seconds first (default: data sampled faster "
                             "than the battery monitor's 5 s window are averaged over it, as the predictor nodes see "
                             "them)")
    parser.add_argument("--no-resample", action="store_true",
                        help=f"{command} the samples as measured, also when they are denser than the monitor's window")


def prepared_data(args: argparse.Namespace, params: PackParams, *, command: str) -> list[Recording]:
    """``fit``'s and ``simulate``'s recordings, prepared alike.

    Loaded, then averaged over ``--resample`` windows or, by default, over the battery monitor's window
    when the data are denser (:func:`~battery_predictor.fitting.resample.as_the_monitor_sees`); says so on
    stderr as ``command`` and sets ``args.resample`` to the window applied (for the provenance).
    """
    from battery_predictor.fitting.resample import as_the_monitor_sees

    recs, args.resample, notice = as_the_monitor_sees(load_data(args.data, pack=params, **data_options(args)),
                                                      args.resample,
                                                      as_measured=getattr(args, "no_resample", False))
    if notice:
        sys.stderr.write(f"{command}: {notice}\n")
        sys.stderr.flush()
    return recs


def fit_data_limits_of(args: argparse.Namespace, fitted: PackParams,
                       recordings: Sequence[Recording]) -> FitDataLimits:
    """The fitted params with the fit data's deepest state and weak group
    (:func:`~battery_predictor.fitting.data_limits.with_fit_data_limits`; ``--no-weak-group-inference`` skips
    the group)."""
    from battery_predictor.fitting.data_limits import with_fit_data_limits

    return with_fit_data_limits(fitted, recordings,
                                infer_weak_group=not getattr(args, "no_weak_group_inference", False))


def weak_group_json(params: PackParams, line: str) -> dict[str, Any]:
    """The fitted params' weak group for ``--json``: its fraction (None without one) and the fit's line about it."""
    from battery_predictor.simulation.extensions import weak_group_fraction

    fraction = weak_group_fraction(params)
    return {"fraction": fraction if "cell_imbalance" in params.extensions else None, "note": line}


def print_deepest_state(deepest: DeepestState | None) -> None:
    """Say which state of the fit data the fitted params keep as their deepest (see :func:`~battery_predictor.fitting.data_limits.with_deepest_state`)."""
    if deepest is not None:
        print(f"deepest state of the fit data: {deepest.voltage_v:.3f} V at {deepest.current_a:.2f} A "
              f"({deepest.temperature_k - 273.15:.1f} degC); routes are not accepted below it when it lies "
              "above the route threshold (thresholds.fit_data_deepest_*)")


def add_data_arguments(parser: argparse.ArgumentParser) -> None:
    """``--data FILE [FILE...]``, ``--no-trim`` and :func:`add_input_check_arguments`."""
    parser.add_argument("--data", nargs="+", required=True, metavar="FILE",
                        help="CSV (time_s, voltage_V, current_A > 0 = discharge[, temperature_C]) or rosbag2 MCAP")
    parser.add_argument("--no-trim", action="store_true",
                        help="keep the samples after the end of the discharge (rests, recharges)")
    add_input_check_arguments(parser)


def _writable_parent(path: Path, option: str) -> None:
    """Raise :class:`InputDataError` unless the nearest existing ancestor of ``path`` is a writable directory."""
    parent = path.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise InputDataError(f"{option} {path}: {parent} is a file, not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputDataError(f"{option} {path}: cannot write into {parent} (permission denied)")


def check_output_file(path: str | os.PathLike[str], option: str, *, suffixes: Sequence[str] = (),
                      overwrite: bool = True) -> Path:
    """Check before any work that ``path`` can be written as a file; returns it as a Path.

    Raises :class:`InputDataError` (one line naming ``option``) when ``path`` is a directory, has a
    suffix outside ``suffixes`` (when given), exists while ``overwrite`` is False, or lies below a
    file or an unwritable directory.
    """
    p = Path(path)
    if p.is_dir():
        raise InputDataError(f"{option} {p}: is a directory; give a file name such as "
                             f"{p / ('out' + (suffixes[0] if suffixes else ''))}")
    if suffixes and p.suffix.lower() not in suffixes:
        raise InputDataError(f"{option} {p}: unsupported file type {p.suffix or '(no suffix)'!r}; use one of "
                             f"{', '.join(suffixes)}")
    if p.exists() and not overwrite:
        raise InputDataError(f"{option} {p}: already exists")
    _writable_parent(p, option)
    return p


def plot_suffixes() -> tuple[str, ...]:
    """File suffixes matplotlib can write (``.png`` first)."""
    from matplotlib.backend_bases import FigureCanvasBase

    others = sorted(f".{ext}" for ext in FigureCanvasBase.get_supported_filetypes() if ext != "png")
    return (".png", *others)


def check_plot_file(path: str | os.PathLike[str], option: str = "--plot") -> Path:
    """:func:`check_output_file` for a figure: the suffix must be one matplotlib writes."""
    return check_output_file(path, option, suffixes=plot_suffixes())


def check_output_dir(path: str | os.PathLike[str], option: str) -> Path:
    """Check before any work that ``path`` can be (or is) a writable directory; returns it as a Path."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputDataError(f"{option} {p}: is a file, expected a directory")
    if p.is_dir():
        if not os.access(p, os.W_OK | os.X_OK):
            raise InputDataError(f"{option} {p}: cannot write into it (permission denied)")
        return p
    _writable_parent(p, option)
    return p


def bag_progress(stream: ReplayStream, end_ns: int | None, desc: str, *,
                 enabled: bool) -> AbstractContextManager[Callable[[float], None]]:
    """:func:`progress_bar` over a replay in bag minutes, with the ``on_step(t_ns)`` callback it needs."""
    last_ns = stream.end_ns if end_ns is None else min(end_ns, stream.end_ns)
    total_min = max(last_ns - stream.start_ns, 0) / 60e9
    return progress_bar(round(total_min, 1), desc, "bag min", enabled=enabled)


def bag_step(update: Callable[[float], None], stream: ReplayStream) -> Callable[[int], None]:
    """The ``on_step(t_ns)`` of :meth:`ReplaySession.play_until` that moves a :func:`bag_progress` bar."""
    return lambda t_ns: update(round((t_ns - stream.start_ns) / 60e9, 1))


@contextlib.contextmanager
def replay_progress(stream: ReplayStream, end_ns: int | None, desc: str, *,
                    enabled: bool) -> Iterator[Callable[[int], None]]:
    """A :func:`bag_progress` bar over a replay up to ``end_ns``; yields its ``on_step(t_ns)``."""
    with bag_progress(stream, end_ns, desc, enabled=enabled) as update:
        yield bag_step(update, stream)


#: A progress bar appears only once its wait has lasted this long, s.
PROGRESS_DELAY_S = 2.0


def progress_wanted(args: argparse.Namespace | None = None, stream: TextIO | None = None) -> bool:
    """Progress bars go to an interactive stderr only, and never with ``--json`` or ``--no-progress``."""
    stream = sys.stderr if stream is None else stream
    if args is not None and (getattr(args, "json", False) or getattr(args, "no_progress", False)):
        return False
    isatty = getattr(stream, "isatty", None)
    return bool(isatty and isatty())


@contextlib.contextmanager
def progress_bar(total: float, desc: str, unit: str, *, enabled: bool, stream: TextIO | None = None,
                 delay_s: float = PROGRESS_DELAY_S) -> Iterator[Callable[[float], None]]:
    """A tqdm bar on ``stream`` (default stderr) shown only after ``delay_s``; yields ``update(done)``.

    ``update`` takes the absolute amount done (same unit as ``total``). When not ``enabled`` it does
    nothing, so callers need no branch.
    """
    if not enabled:
        yield lambda _done: None
        return
    from tqdm import tqdm

    # shutil falls back to 80 x 24 where the terminal reports 0 x 0 (tqdm would then draw nothing)
    size = shutil.get_terminal_size()
    # disable=False explicitly: TQDM_DISABLE (set for a moment by quiet_pybamm in any thread) only
    # changes tqdm's defaults, and ``enabled`` has already decided
    bar = tqdm(total=total, desc=desc, unit=unit, file=sys.stderr if stream is None else stream, delay=delay_s,
               ncols=size.columns, nrows=size.lines, leave=False, disable=False)

    def update(done: float) -> None:
        bar.n = min(done, total)
        bar.update(0)  # draws only after the delay, at most every mininterval

    try:
        yield update
    finally:
        bar.close()
