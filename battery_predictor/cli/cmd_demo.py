"""``battery-predictor demo``: the main job on bundled data, through the real ROS 2 nodes.

1. Information robot (temi): a bundled discharge bag (relay topics, with the
   true time until 13.30 V in its metadata) is replayed into ``battery_monitor``
   and ``predictor`` (``battery-predictor replay`` in-process, ``/clock`` from
   the bag, lock step); the remaining runtime published on ``/remaining_runtime``
   after 30, 60, ..., 300 min is printed against the truth; then ``/feasible_tasks``
   is asked which of a few passengers' requests the robot can still take.
2. Luggage robot (Ranger Mini): a bundled bag (BatteryState) is replayed up to a
   given time, and ``/can_accept_route`` is asked over the middleware for the
   paper's longest route with 20, 40, 60 and 80 kg; the decisions are printed;
   then ``/plan_route`` plans a job from where the robot stands.
3. Where the figures come from: the bundled bags are emulated (made from the shipped params);
   the figures measured on real cells (``docs/runtime_real_data``, made by
   ``battery-predictor evaluate-runtime``) are printed beside them.

The nodes run on a ROS domain of their own with discovery kept on this machine,
so the demo never talks to another ROS system. Takes about a minute.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from battery_predictor.nodes.client import Context
    from battery_predictor.nodes.replay_session import ReplaySession

REPO = Path(__file__).resolve().parents[2]
BAGS = REPO / "bags"
NODE_PARAMS = REPO / "params" / "ros"
DEMO_TEMI_BAG = "temi_dynamic_pack1"
DEMO_RANGER_BAG = "ranger_stepwise_pack1"
DEMO_RANGER_AT_MIN = 341.0
REAL_DATA_SUMMARY = REPO / "docs" / "runtime_real_data" / "summary.json"
PAYLOADS_KG = (20.0, 40.0, 60.0, 80.0)
#: The passengers' requests of the feasible-tasks question: (name, kind, duration_s, destination).
DEMO_TASKS = (("tickets and timetable", "information", 300.0, ""), ("guide to the restroom", "navigation", 0.0,
              "restroom"), ("long conversation", "information", 2700.0, ""),
              ("guide to the ticket machine", "navigation", 0.0, "ticket_machine"))
#: The luggage job of the planning question.
DEMO_JOB = dict(start_node="platform13_north", pickup="platform11_south", dropoff="platform13_south", payload_kg=80.0)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="replay a bundled temi bag through the nodes (runtime vs truth) and ask "
                                    "/can_accept_route for the longest route at 20-80 kg from a bundled Ranger state",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("--temi-bag", default=DEMO_TEMI_BAG, help=f"bundled temi bag (default {DEMO_TEMI_BAG})")
    p.add_argument("--ranger-bag", default=DEMO_RANGER_BAG, help=f"bundled Ranger bag (default {DEMO_RANGER_BAG})")
    p.add_argument("--ranger-at-min", type=float, default=DEMO_RANGER_AT_MIN,
                   help=f"replay the Ranger bag up to this time, min (default {DEMO_RANGER_AT_MIN:g})")
    p.add_argument("--rate", type=float, default=0.0, help="replay rate (default 0: as fast as the nodes take it)")
    p.add_argument("--runtime-period", type=float, default=300.0,
                   help="predictor.runtime_period_s in the replay, bag seconds (default 300)")
    p.add_argument("--out", default=None,
                   help="keep the output bag and plot in this directory (default: a temporary one, removed at the end)")
    p.set_defaults(func=run)


def _bag(name: str) -> Path:
    from battery_predictor.errors import InputDataError

    path = Path(name) if Path(name).exists() else BAGS / name
    if not path.exists():
        raise InputDataError(f"{path}: bundled bag missing (regenerate with 'make bags')")
    return path


def _feasible_tasks(session: ReplaySession, at_min: float) -> list[str]:
    """Ask /feasible_tasks for DEMO_TASKS at the entrance; the lines to print."""
    from battery_predictor.nodes.client import feasible_tasks

    r = feasible_tasks(session, DEMO_TASKS, "entrance")
    lines = [f"   /feasible_tasks after {at_min:.0f} min, robot at the entrance, greedy (each task after those "
             "accepted; the walk back to the charger must stay above the cut-off):"]
    if not r.valid:
        lines.append(f"   not valid: {r.reason}")
    lines.append(f"   {'task':<28} {'min':>5} {'V at end':>9} {'margin':>8} {'left after':>11} {'P(ok)':>6}  feasible")
    for t in r.results:
        lines.append(f"   {t.name:<28} {t.duration_s / 60:>5.1f} {t.end_voltage_v:>7.2f} V {t.margin_v:>+6.2f} V "
                     f"{t.remaining_after_s / 60:>7.0f} min {t.probability_feasible:>6.3f}  {'yes' if t.feasible else 'no'}")
    lines.append(f'   the robot says: "{r.summary}"')
    lines.append(f"   ({r.reason})")
    return lines


def _route_outcome(r: Any) -> str:
    """The planned route's predicted end, or that the pack does not finish it (its voltage is then NaN)."""
    if not math.isfinite(r.predicted_voltage_v):
        return (f"the pack does not finish it (a cell reaches its cut-off on the way), threshold "
                f"{r.threshold_voltage_v:.2f} V")
    return (f"{r.predicted_voltage_v:.2f} V at the standstill current after it, threshold {r.threshold_voltage_v:.2f} V, "
            f"margin {r.margin_v:+.2f} V, probability above the threshold {r.probability_above_threshold:.3f} "
            f"(accepted at risk {r.risk:.2f})")


def _plan_route(session: ReplaySession) -> list[str]:
    """Ask /plan_route for DEMO_JOB; the lines to print."""
    from battery_predictor.nodes.client import PLANNED_ROUTE_KINDS, plan_route

    r = plan_route(session, DEMO_JOB)
    lines = [f"   /plan_route: robot at {DEMO_JOB['start_node']}, {DEMO_JOB['payload_kg']:.0f} kg of luggage from "
             f"{DEMO_JOB['pickup']} to {DEMO_JOB['dropoff']}, then back to the charger:",
             f"   route {' -> '.join(r.nodes)} ({r.length_m:.0f} m, {len(r.sections)} sections, "
             f"{r.route_duration_s / 60:.1f} min, {r.route_charge_ah:.2f} Ah)",
             f"   {'accept' if r.accepted else 'reject'}: " + _route_outcome(r)]
    for a in r.alternatives:
        soc = f", charge to SOC >= {a.required_soc:.3f}" if a.required_soc == a.required_soc else ""
        lines.append(f"   alternative, {PLANNED_ROUTE_KINDS.get(a.kind, a.kind)}: {'feasible' if a.feasible else 'not feasible'}{soc}")
    lines.append(f"   reason: {r.reason}")
    return lines


def _temi(context: Context, bag: Path, out: Path, rate: float, runtime_period_s: float) -> None:
    from battery_predictor.cli.common import progress_wanted, replay_progress
    from battery_predictor.nodes.replay_run import replay_into_nodes
    from battery_predictor.replay import DEFAULT_CHECKPOINTS_MIN, error_summary, read_replay_stream, runtime_truth

    stream = read_replay_stream(bag)
    truth = runtime_truth(stream.metadata)
    params = NODE_PARAMS / "temi_nodes.yaml"
    print(f"1) information robot (temi): {bag.name} replayed into battery_monitor + predictor "
          f"({params.relative_to(REPO)})")
    print(f"   {stream.style} topics, {len(stream.messages)} messages over {stream.duration_s / 60:.0f} min; "
          + (f"truth: {truth.stop_voltage_v:.2f} V reached after {truth.runtime_s / 60:.1f} min" if truth else
             "no runtime truth in this bag"), flush=True)
    # the checkpoints (30..300 min, as the paper's 5.1.6) need the bag only up to the last one
    last_s = 60.0 * max(DEFAULT_CHECKPOINTS_MIN) + runtime_period_s
    result = replay_into_nodes(
        stream, context=context, params_file=params, out_bag=out / "temi_outputs",
        bag_metadata={"replay_of": str(bag), "params": str(params)}, plot=out / "temi_remaining_runtime.png",
        plot_title=f"{bag.name}: /remaining_runtime vs truth", rate=rate,
        overrides={"runtime_period_s": runtime_period_s},
        end_ns=stream.ros_time_ns(last_s) if truth and truth.runtime_s > last_s else None,
        progress=lambda end_ns: replay_progress(stream, end_ns, "   replay", enabled=progress_wanted()),
        while_open=lambda session: _feasible_tasks(session, (session.now_ns() - stream.start_ns) / 6e10))
    stats, points, checkpoints, png = result.stats, result.points, result.checkpoints, result.plot
    rejected, task_lines = result.rejected_total, result.during
    print(f"   played {stats.bag_s / 60:.0f} bag min in {stats.wall_s:.0f} s; {sum(p.valid for p in points)} valid predictions, "
          f"{rejected} samples rejected by the monitor")
    if checkpoints:
        print(f"   {'after':>8} {'predicted':>10} {'P10..P90':>14} {'true':>8} {'error':>8}")
        for c in checkpoints:
            print(f"   {c.checkpoint_min:>4.0f} min {c.predicted_min:>6.1f} min {c.p10_min:>6.0f}..{c.p90_min:<4.0f} min "
                  f"{c.true_min:>4.0f} min {c.error_min:>+5.1f} min")
        inside = sum(c.p10_min <= c.true_min <= c.p90_min for c in checkpoints)
        print(f"   truth inside P10..P90 at {inside} of {len(checkpoints)} checkpoints (calibration over whole "
              "discharges: docs/uncertainty)")
        e = error_summary(checkpoints)
        print(f"   MAE {e['mae_min']:.1f} min, max |error| {e['max_abs_error_min']:.1f} min, MAPE {e['mape_pct']:.1f} % "
              "(seed paper, real Temi: MAE 14.92 min, MAPE 18.9 %)")
        print("   the node's load model is 'auto': until the cycle shows otherwise, the Temi params' prior, a constant")
        print("   current (operating.load_prior_power_fraction; docs/runtime_real_data, \"The Temi's load prior\")")
    print("\n".join(task_lines))
    print(f"   plot {png}; node outputs {out / 'temi_outputs'} (MCAP)\n")


def _ranger(context: Context, bag: Path, at_min: float, rate: float) -> None:
    from battery_predictor.cli.common import progress_wanted, replay_progress
    from battery_predictor.nodes.client import can_accept_route
    from battery_predictor.nodes.replay_session import ReplaySession
    from battery_predictor.profiles.ranger import longest_route
    from battery_predictor.replay import read_replay_stream

    stream = read_replay_stream(bag)
    params = NODE_PARAMS / "ranger_nodes.yaml"
    with ReplaySession(stream, context=context, params_file=str(params), rate=rate,
                       predictor_overrides={"runtime_period_s": 600.0}) as session:
        end_ns = stream.ros_time_ns(at_min * 60.0)
        with replay_progress(stream, end_ns, "   replay", enabled=progress_wanted()) as on_step:
            session.play_until(end_ns, on_step=on_step)
        state = session.predictor.route_core.latest_state()
        print(f"2) luggage robot (Ranger Mini): {bag.name} replayed to {at_min:g} min "
              f"({params.relative_to(REPO)})")
        if state is not None:
            print(f"   pack state: {state[1]:.2f} V at {state[2]:.2f} A, {state[3] - 273.15:.1f} degC")
        route = longest_route(80.0)
        print(f"   /can_accept_route, the paper's longest route ({route.length_m:.0f} m, "
              f"{route.duration_s / 60:.1f} min, payload on the loaded leg):")
        print(f"   {'payload':>8} {'decision':>9} {'V after':>9} {'threshold':>10} {'margin':>8} {'charge':>8} "
              f"{'P(above)':>9} {'P10 V':>8}")
        reasons = []
        for kg in PAYLOADS_KG:
            r = can_accept_route(session, longest_route(kg).sections)
            print(f"   {kg:>5.0f} kg {'accept' if r.accepted else 'reject':>9} {r.predicted_voltage_v:>7.2f} V "
                  f"{r.threshold_voltage_v:>8.2f} V {r.margin_v:>+6.2f} V {r.route_charge_ah:>5.2f} Ah "
                  f"{r.probability_above_threshold:>9.3f} {r.voltage_at_risk_v:>6.2f} V")
            reasons.append(f"{kg:.0f} kg: {r.reason}")
        print("   reasons:\n     " + "\n     ".join(reasons))
        print("\n".join(_plan_route(session)))


@contextlib.contextmanager
def output_dir(out: str | None) -> Iterator[Path]:
    """``--out`` checked and created, or a temporary directory removed when the demo ends."""
    if out is None:
        with tempfile.TemporaryDirectory(prefix="battery-predictor-demo-") as tmp:
            yield Path(tmp)
        return
    from battery_predictor.cli.common import check_output_dir
    from battery_predictor.errors import InputDataError

    path = check_output_dir(out, "--out")
    if (path / "temi_outputs").exists():
        raise InputDataError(f"--out {path}: {path / 'temi_outputs'} exists (choose another --out)")
    path.mkdir(parents=True, exist_ok=True)
    yield path


def _real_data_figures(path: Path) -> None:
    """Print the measured-cell runtime figures beside the emulated ones (what a reader should trust)."""
    import json

    print("3) where these figures come from: the bags above are EMULATED (bags/README.md), made from the")
    print("   shipped params, so the model starts next to the truth.")
    if not path.is_file():
        print(f"   no measured-data figures found ({path.relative_to(REPO)} is missing)")
        return
    summary = json.loads(path.read_text())
    pooled = summary["pooled"]
    cells = ", ".join(Path(r["source"]).stem for r in summary["per_recording"])
    print(f"   MEASURED cells ({Path(summary['params']).name}; {len(summary['per_recording'])} held-out recordings: "
          f"{cells}), {path.parent.relative_to(REPO)}/report.md:")
    for name, fig in pooled.items():
        print(f"      {name:<18} remaining-runtime MAE {fig['mae_min']:.1f} min, bias {fig['bias_min']:+.1f} min, "
              f"{fig['answered']}/{fig['checkpoints']} answered")
    interval = summary.get("pooled_interval")
    if interval:
        print(f"      truth inside the predictor's P10..P90 at {interval['inside_pct']:.0f} % of {interval['intervals']} "
              "checkpoints (target 80 +- 10 %; docs/uncertainty)")


def run(args: argparse.Namespace) -> int:
    from battery_predictor.nodes.client import isolated_context

    temi_bag, ranger_bag = _bag(args.temi_bag), _bag(args.ranger_bag)
    with output_dir(args.out) as out:
        context = isolated_context()
        try:
            _temi(context, temi_bag, out, args.rate, args.runtime_period)
            _ranger(context, ranger_bag, args.ranger_at_min, args.rate)
        finally:
            context.try_shutdown()
    _real_data_figures(REAL_DATA_SUMMARY)
    if args.out is None:
        print("(the plot and node outputs were in a temporary directory, now removed; pass --out DIR to keep them)")
    return 0
