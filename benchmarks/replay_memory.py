"""Memory of the nodes over a 24 h replay (issue 18): the process's RSS per bag hour.

A 24 h bag (relay topics) of the information robot's pack is made on the SPM engine: three cycles,
each a Temi usage day (seeded usage profile, until 13.3 V or 6 h) and a 2 h charge at 5 A, sampled
every 2 s. It is replayed through ``battery_monitor`` and ``predictor`` in one process
(:class:`~battery_predictor.nodes.replay_session.ReplaySession`, lock step, as fast as the nodes
take it, a runtime update every 60 bag seconds), and the process's resident set size is printed
every bag hour with the wall time. The replay harness's recorder keeps every output message in
memory (the tests read them back); it is emptied every bag hour after counting, so the figure is
the nodes' memory (``--keep-outputs`` keeps them, to see the harness's share).

Run: ``.venv/bin/python benchmarks/replay_memory.py [--hours 24] [--keep DIR]``
"""

from __future__ import annotations

import argparse
import random
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SAMPLE_S = 2.0


def rss_mb() -> float:
    """Resident set size of this process in MB (Linux ``/proc/self/statm``)."""
    import os

    pages = int(Path("/proc/self/statm").read_text().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 1e6


def day_recording(hours: float):
    """Discharge days and charges of the Temi pack on the engine, as one Recording (2 s samples)."""
    from battery_predictor.params import load_params
    from battery_predictor.profiles.temi import generate_usage_profile
    from battery_predictor.recording import Recording
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.engine import EngineSimulator

    params = load_params(REPO / "params" / "temi.yaml")
    sim = EngineSimulator()
    times, volts, currents = [], [], []
    t0, cycle = 0.0, 0
    while t0 < hours * 3600.0:
        profile = generate_usage_profile(seed=100 + cycle, max_duration_s=6 * 3600)
        day = StepLoad.from_profile(profile).resample(SAMPLE_S)
        charge = StepLoad(np.array([0.0]), np.array([-5.0]), 2 * 3600.0)
        for load, soc in ((day, 1.0), (charge, 0.05)):
            grid = np.arange(0.0, load.end_s, SAMPLE_S)
            res = sim.simulate(params, SimulationRequest(load=load, initial_soc=soc, output_time_s=grid))
            times.append(t0 + res.time_s)
            volts.append(res.pack_voltage_v)
            currents.append(res.pack_current_a)
            t0 += float(res.time_s[-1]) + SAMPLE_S
        cycle += 1
    t, v, i = (np.concatenate(x) for x in (times, volts, currents))
    keep = t < hours * 3600.0
    return Recording(time_s=t[keep], voltage_v=np.round(v[keep], 3), current_a=np.round(i[keep], 2),
                     temperature_k=np.full(int(keep.sum()), 298.15), source="replay_memory")


def empty_outputs(recorder) -> int:
    """Empty the recorder's kept messages; returns how many valid runtime answers it held."""
    return sum(1 for topic, msgs in recorder.drain().items() if topic.endswith("remaining_runtime")
               for m in msgs if m.valid)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--keep", default=None, help="write the bag here instead of a temporary directory")
    ap.add_argument("--keep-outputs", action="store_true", help="do not empty the harness's recorded outputs")
    args = ap.parse_args()

    import os

    import rclpy
    from rclpy.context import Context

    from battery_predictor.io.bags import write_recording_bag
    from battery_predictor.nodes.replay_session import ReplaySession
    from battery_predictor.replay import read_replay_stream

    tic = time.perf_counter()
    rec = day_recording(args.hours)
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(args.keep) if args.keep else Path(tmp) / "temi_24h"
        write_recording_bag(rec, bag, style="relay", overwrite=True)  # the information robot's topics
        print(f"bag: {rec.time_s.size} samples over {rec.time_s[-1] / 3600:.1f} h "
              f"(made in {time.perf_counter() - tic:.0f} s)")
        stream = read_replay_stream(bag)
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        context = Context()
        rclpy.init(args=["replay-memory"], context=context, domain_id=random.randrange(150, 230))
        rows: list[tuple[float, float, float]] = []
        wall0 = time.monotonic()
        next_h = [0.0]
        valid = [0]

        def sample(t_ns: int) -> None:
            hour = (t_ns - stream.start_ns) / 3.6e12
            if hour >= next_h[0]:
                if not args.keep_outputs:
                    valid[0] += empty_outputs(session.recorder)
                rows.append((hour, rss_mb(), time.monotonic() - wall0))
                next_h[0] += 1.0

        try:
            with ReplaySession(stream, context=context, params_file=str(REPO / "params/ros/temi_nodes.yaml"),
                               predictor_overrides={"runtime_period_s": 60.0}, rate=0) as session:
                session.play_until(on_step=sample)
                valid[0] += empty_outputs(session.recorder)
                rows.append(((stream.end_ns - stream.start_ns) / 3.6e12, rss_mb(), time.monotonic() - wall0))
        finally:
            context.try_shutdown()
    print(f"{'bag h':>6} {'RSS MB':>8} {'wall s':>8}")
    for hour, mb, wall in rows:
        print(f"{hour:>6.1f} {mb:>8.1f} {wall:>8.0f}")
    after_2h = next((mb for hour, mb, _ in rows if hour >= 2.0), rows[0][1])
    print(f"RSS growth from bag hour 2 to the end: {rows[-1][1] - after_2h:+.1f} MB; "
          f"{valid[0]} valid runtime answers")


if __name__ == "__main__":
    main()
