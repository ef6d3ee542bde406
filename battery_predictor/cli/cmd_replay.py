"""``battery-predictor replay``: play a bag into the nodes and record what they publish.

    battery-predictor replay BAG --params P.yaml [--rate X] [--out DIR] [--pack FITTED.yaml]
                             [--runtime-period S] [--overwrite] [--json]

Starts ``battery_monitor`` and ``predictor`` (parameters from P.yaml, with
``use_sim_time``) in this process, publishes the bag's battery topics with
``/clock`` = their bag time, keeping their relative timing X times faster
(``--rate 0``: as fast as possible; the replay never outruns the nodes, see
:mod:`battery_predictor.nodes.replay_session`), and records the nodes' outputs
(``pack_state``, ``remaining_runtime``, ``/diagnostics``) into a new rosbag2
MCAP bag ``DIR/outputs`` that Foxglove (the ``.mcap`` file) and ``rosbags`` open.
``DIR/remaining_runtime.png`` plots the predicted remaining runtime and the true
one: the lab's truth when the bag carries it (the bundled information-robot bags;
checkpoints at 30, 60, ..., 300 min), otherwise the measured recording's own end
of discharge at the cut-off the predictor published, when the recording ends
there (checkpoints at 10, 20, ..., 90 % of the discharge; the same truth as
``evaluate-runtime``). Checkpoint errors and MAE are printed.
"""

from __future__ import annotations

import argparse
import math
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from battery_predictor.nodes.client import Context
    from battery_predictor.params import PackParams
    from battery_predictor.replay import ReplayStream, RuntimePoint, RuntimeTruth


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="play a bag into the nodes, record their outputs (MCAP) and plot the runtime",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("bag", help="rosbag2 directory or .mcap file with BatteryState or relay topics")
    p.add_argument("--params", required=True, metavar="P.yaml",
                   help="node parameters (battery_monitor: / predictor: ros__parameters), e.g. params/ros/temi_nodes.yaml")
    p.add_argument("--rate", type=float, default=1.0,
                   help="play X times faster than recorded (default 1; 0 = as fast as the nodes can take it)")
    p.add_argument("--out", default=None, help="output directory (default: ./<bag name>_replay)")
    p.add_argument("--overwrite", action="store_true", help="replace the outputs of an earlier replay in --out")
    p.add_argument("--pack", default=None, metavar="PACK.yaml", help="fitted pack params; overrides predictor.params_file")
    p.add_argument("--runtime-period", type=float, default=None, metavar="S",
                   help="override predictor.runtime_period_s (bag seconds between runtime updates)")
    p.add_argument("--shared-domain", action="store_true",
                   help="run the nodes on the environment's ROS domain (ROS_DOMAIN_ID) so other tools can watch live; "
                        "by default a replay runs on a private domain on this machine, so it neither publishes "
                        "recorded battery states into a running robot's graph nor hears other publishers")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run)


def replay_bag(bag: str, params: str, *, rate: float = 1.0, out_dir: str | Path | None = None,
               overwrite: bool = False, pack: str | None = None, runtime_period_s: float | None = None,
               context: Context | None = None, quiet: bool = False, shared_domain: bool = False) -> dict:
    """Replay ``bag`` (see the module docstring); returns a summary dict.

    ``context``: an initialised rclpy context to use (default: a private one on a random ROS domain,
    discovery on this machine only; with ``shared_domain``, rclpy's global one on the environment's
    domain), shut down after the replay unless given.
    """
    from battery_predictor.cli._ros_params import check_node_params_file
    from battery_predictor.cli.common import check_output_dir
    from battery_predictor.errors import InputDataError
    from battery_predictor.nodes.client import isolated_context, ros_context
    from battery_predictor.nodes.replay_session import default_output_dir
    from battery_predictor.replay import read_replay_stream

    pack_params = check_node_params_file(params, pack=pack)
    if not (rate >= 0 and not math.isnan(rate)):
        raise InputDataError(f"--rate is {rate} (must be >= 0)")
    out = check_output_dir(out_dir or default_output_dir(bag), "--out")
    stream = read_replay_stream(bag)
    _warn_if_sparse(stream, params)
    bag_out, png = _prepared_output(out, overwrite)
    overrides: dict[str, Any] = {}
    if pack:
        overrides["params_file"] = str(pack)
    if runtime_period_s is not None:
        overrides["runtime_period_s"] = float(runtime_period_s)
    own = isolated_context() if context is None and not shared_domain else None
    try:
        with ros_context(context or own) as context:
            result = _run(stream, context, bag, params, pack_params, bag_out, png, rate, overrides, quiet)
    finally:
        if own is not None:
            own.try_shutdown()
    return _summary(stream, result, bag_out, png)


def sparse_input_warning(source: str, sample_times_s: Any, limits_s: dict[str, float]) -> str | None:
    """Why most answers of a replay will be stale, or None: the bag's battery samples are typically further
    apart (median gap) than a node's ``stale_after_s`` (``limits_s``: node name -> s).

    ``evaluate-runtime`` averages the same recording into windows without a notion of staleness, so without
    this a replay of a sparsely sampled recording (the LG M50's 20-60 s records) disagrees with it silently.
    """
    import numpy as np

    t = np.asarray(sample_times_s, dtype=float)
    gaps = np.diff(t[np.isfinite(t)])
    gaps = gaps[gaps > 0]
    if not gaps.size:
        return None
    typical = float(np.median(gaps))
    over = {name: lim for name, lim in limits_s.items() if math.isfinite(lim) and typical > lim}
    if not over:
        return None
    names = ", ".join(f"{name} stale_after_s {lim:g} s" for name, lim in over.items())
    return (f"{source}: its battery samples are {typical:.0f} s apart (median), more than {names}: most runtime "
            "answers will be stale (invalid); raise stale_after_s in the node params file for this recording")


def _warn_if_sparse(stream: ReplayStream, params: str) -> None:
    """Warn (one line) when the bag's samples are too sparse for the node params' ``stale_after_s``."""
    import warnings

    import yaml

    from battery_predictor.errors import BatteryPredictorError
    from battery_predictor.monitor.core import MonitorConfig
    from battery_predictor.prediction.core import PredictorConfig

    try:
        data = yaml.safe_load(Path(params).read_text()) or {}
        rec = stream.recording(drop_nan=True)
    except (BatteryPredictorError, OSError, yaml.YAMLError):
        return

    def limit(node: str, default: float) -> float:
        section = data.get(node) if isinstance(data, dict) else None
        values = section.get("ros__parameters", {}) if isinstance(section, dict) else {}
        value = values.get("stale_after_s", default) if isinstance(values, dict) else default
        return float(value) if isinstance(value, (int, float)) else default

    message = sparse_input_warning(stream.source, rec.time_s,
                                   {"battery_monitor": limit("battery_monitor", MonitorConfig.stale_after_s),
                                    "predictor": limit("predictor", PredictorConfig.stale_after_s)})
    if message:
        warnings.warn(message, stacklevel=2)


def _prepared_output(out: Path, overwrite: bool) -> tuple[Path, Path]:
    """The output bag and plot paths in ``out``; an existing output bag is removed only with ``overwrite``."""
    from battery_predictor.errors import InputDataError

    bag_out, png = out / "outputs", out / "remaining_runtime.png"
    if bag_out.exists():
        if not overwrite:
            raise InputDataError(f"{bag_out}: exists (pass --overwrite or another --out)")
        if not (bag_out / "metadata.yaml").exists() and any(bag_out.iterdir()):
            raise InputDataError(f"{bag_out}: exists and is not a bag; not removing it")
        shutil.rmtree(bag_out)
    out.mkdir(parents=True, exist_ok=True)
    return bag_out, png


def _run(stream: ReplayStream, context: Context | None, bag: str, params: str, pack_params: PackParams | None,
         bag_out: Path, png: Path, rate: float, overrides: dict[str, Any], quiet: bool) -> Any:
    """Feed ``stream`` into the nodes on ``context`` (None: rclpy's global one); the replay's result."""
    from battery_predictor.cli.common import progress_wanted, replay_progress
    from battery_predictor.nodes.replay_run import replay_into_nodes

    if not quiet:
        print(f"replay: {stream.source}: {stream.style} topics {', '.join(stream.topics)}, "
              f"{len(stream.messages)} messages over {stream.duration_s / 60:.1f} min"
              + (f", at most {rate:g}x" if rate > 0 else ", as fast as possible"), flush=True)
    return replay_into_nodes(
        stream, context=context, params_file=params, out_bag=bag_out, plot=png,
        plot_title=f"{Path(stream.source).name}: remaining runtime", rate=rate,
        bag_metadata={"replay_of": str(bag), "params": str(params), "rate": rate}, overrides=overrides,
        progress=lambda end_ns: replay_progress(stream, end_ns, "replay", enabled=not quiet and progress_wanted()),
        truth_from_points=lambda points: measured_truth(stream, pack_params, points))


def _summary(stream: ReplayStream, result: Any, bag_out: Path, png: Path) -> dict:
    """The JSON summary of a finished replay."""
    from battery_predictor.replay import error_summary

    stats, points, truth, checkpoints = result.stats, result.points, result.truth, result.checkpoints
    return {
        "bag": stream.source,
        "output_bag": str(bag_out),
        "plot": str(png),
        "steps": stats.steps,
        "messages": stats.messages,
        "bag_s": stats.bag_s,
        "wall_s": stats.wall_s,
        "pack_states": result.pack_states,
        "runtime_messages": len(points),
        "valid_runtime_messages": sum(p.valid for p in points),
        "rejected_samples": result.rejected,
        "max_diagnostic_level": max(result.diagnostic_levels, default=0),
        "truth_runtime_min": truth.runtime_s / 60 if truth else None,
        "truth_source": truth.source if truth else None,
        "checkpoints": [{"checkpoint_min": c.checkpoint_min, "prediction_time_min": c.time_s / 60,
                         "predicted_min": c.predicted_min, "true_min": c.true_min, "error_min": c.error_min}
                        for c in checkpoints],
        "errors": error_summary(checkpoints) if checkpoints else None,
    }


def measured_truth(stream: ReplayStream, pack_params: PackParams | None,
                   points: list[RuntimePoint]) -> RuntimeTruth | None:
    """The truth of a bag without one in its metadata: the measured discharge's end at the published cut-off.

    The recording is the stream's own messages (:meth:`ReplayStream.recording`, as the bag reader
    decodes them). None when the pack is unknown, no runtime message names a cut-off, the battery
    samples cannot be decoded, or the recording's end is not the cut-off.
    """
    from battery_predictor.errors import BatteryPredictorError
    from battery_predictor.evaluation.runtime_eval import recording_runtime_truth

    cutoffs = [p.cutoff_voltage_v for p in points if math.isfinite(p.cutoff_voltage_v) and p.cutoff_voltage_v > 0]
    if pack_params is None or not cutoffs:
        return None
    try:
        rec = stream.recording(drop_nan=True)
    except BatteryPredictorError:
        return None
    offset_s = stream.recording_time_s(stream.start_ns) - float(rec.time_s[0])
    return recording_runtime_truth(pack_params, rec, cutoffs[-1], time_offset_s=offset_s)


def print_summary(summary: dict) -> None:
    """Human-readable replay summary."""
    print(f"played {summary['messages']} messages ({summary['bag_s'] / 60:.1f} bag min) in {summary['wall_s']:.1f} s; "
          f"{summary['pack_states']} pack states, {summary['valid_runtime_messages']}/{summary['runtime_messages']} "
          "valid runtime predictions")
    if summary["rejected_samples"]:
        print(f"rejected samples: {summary['rejected_samples']}")
    if summary["checkpoints"]:
        source = summary.get("truth_source") or "metadata"
        print(f"true runtime {summary['truth_runtime_min']:.1f} min ({'the lab truth in the bag' if source == 'metadata' else source})")
        print(f"  {'at min':>7} {'pred. at':>9} {'predicted':>10} {'true':>8} {'error':>8}   (min)")
        for c in summary["checkpoints"]:
            print(f"  {c['checkpoint_min']:>7.1f} {c['prediction_time_min']:>9.1f} {c['predicted_min']:>10.1f} "
                  f"{c['true_min']:>8.1f} {c['error_min']:>+8.1f}")
        e = summary["errors"]
        print(f"  MAE {e['mae_min']:.1f} min, max |error| {e['max_abs_error_min']:.1f} min, MAPE {e['mape_pct']:.1f} % "
              "(seed paper: MAE 14.92 min, MAPE 18.9 %)")
    print(f"wrote {summary['output_bag']} and {summary['plot']}")


def run(args: argparse.Namespace) -> int:
    from battery_predictor.cli.common import print_json

    summary = replay_bag(args.bag, args.params, rate=args.rate, out_dir=args.out, overwrite=args.overwrite,
                         pack=args.pack, runtime_period_s=args.runtime_period, quiet=args.json,
                         shared_domain=args.shared_domain)
    if args.json:
        print_json(summary)
    else:
        print_summary(summary)
    return 0
