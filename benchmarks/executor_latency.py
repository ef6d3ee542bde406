"""Executors side by side: rclpy's MultiThreadedExecutor, the nodes' StartedMultiThreadedExecutor, single-threaded.

For each executor, in one process and one run: two nodes (publisher, subscriber) on the
executor spinning in a background thread; the main thread publishes ``--messages``
``std_msgs/Int64`` one at a time and waits (polling every ``--poll`` s, as the lock-step
replay does) until the subscription callback ran. Prints the publish -> callback latency
(median, p95, max, ms) and the process CPU time spent, then the wall time per step of a
lock-step replay of the first ``--replay-minutes`` of ``bags/temi_dynamic_pack1`` with
each multi-threaded executor.

Why: rclpy 7.1.x (Jazzy) re-yields a callback that is queued in the thread pool but not yet
started, so its spinning thread busy-loops (rclpy issue #1452, fixed upstream by PR #1547).

Usage: .venv/bin/python benchmarks/executor_latency.py [--messages 200] [--poll 0.0002]
                                                      [--replay-minutes 20] [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _latency(kind: str, messages: int, poll_s: float, domain_id: int) -> dict:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
    from std_msgs.msg import Int64

    from battery_predictor.nodes.executor import StartedMultiThreadedExecutor

    context = Context()
    rclpy.init(args=[], context=context, domain_id=domain_id)
    make = {"rclpy MultiThreadedExecutor(4)": lambda: MultiThreadedExecutor(4, context=context),
            "StartedMultiThreadedExecutor(4)": lambda: StartedMultiThreadedExecutor(4, context=context),
            "SingleThreadedExecutor": lambda: SingleThreadedExecutor(context=context)}[kind]
    pub_node = rclpy.create_node("bench_pub", context=context)
    sub_node = rclpy.create_node("bench_sub", context=context)
    got: list[float] = []
    sub_node.create_subscription(Int64, "/bench", lambda _m: got.append(time.monotonic()), 10)
    pub = pub_node.create_publisher(Int64, "/bench", 10)
    executor = make()
    executor.add_node(pub_node)
    executor.add_node(sub_node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    while pub.get_subscription_count() < 1:
        time.sleep(0.01)
    time.sleep(0.5)
    latencies_ms = []
    cpu0 = time.process_time()
    for k in range(messages):
        n = len(got)
        tic = time.monotonic()
        pub.publish(Int64(data=k))
        while len(got) == n:
            time.sleep(poll_s)
        latencies_ms.append((got[-1] - tic) * 1e3)
    cpu_s = time.process_time() - cpu0
    executor.shutdown()
    thread.join(timeout=5.0)
    pub_node.destroy_node()
    sub_node.destroy_node()
    context.try_shutdown()
    latencies_ms.sort()
    return {"executor": kind, "median_ms": statistics.median(latencies_ms),
            "p95_ms": latencies_ms[int(0.95 * (len(latencies_ms) - 1))], "max_ms": latencies_ms[-1],
            "cpu_s": cpu_s}


def _replay(kind: str, minutes: float, domain_id: int) -> dict:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import MultiThreadedExecutor

    from battery_predictor.nodes import replay_session
    from battery_predictor.replay import read_replay_stream

    stream = read_replay_stream(REPO / "bags" / "temi_dynamic_pack1")
    context = Context()
    rclpy.init(args=[], context=context, domain_id=domain_id)
    original = replay_session.StartedMultiThreadedExecutor
    if kind.startswith("rclpy"):
        replay_session.StartedMultiThreadedExecutor = MultiThreadedExecutor  # type: ignore[misc]
    try:
        with replay_session.ReplaySession(
                stream, context=context, params_file=str(REPO / "params/ros/temi_nodes.yaml"),
                predictor_overrides={"runtime_period_s": 300.0}, rate=0) as session:
            stats = session.play_until(stream.ros_time_ns(60.0 * minutes))
    finally:
        replay_session.StartedMultiThreadedExecutor = original  # type: ignore[misc]
        context.try_shutdown()
    return {"executor": kind, "steps": stats.steps, "wall_s": stats.wall_s,
            "ms_per_step": 1e3 * stats.wall_s / max(stats.steps, 1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=200)
    ap.add_argument("--poll", type=float, default=0.0002, help="main thread's polling interval (s)")
    ap.add_argument("--replay-minutes", type=float, default=20.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    import os
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    domain = 150 + os.getpid() % 50
    kinds = ["rclpy MultiThreadedExecutor(4)", "StartedMultiThreadedExecutor(4)", "SingleThreadedExecutor"]
    latency = [_latency(k, args.messages, args.poll, domain) for k in kinds]
    replay = [_replay(k, args.replay_minutes, domain) for k in kinds[:2]] if args.replay_minutes > 0 else []
    if args.json:
        print(json.dumps({"latency": latency, "replay": replay}, indent=2))
        return 0
    print(f"publish -> callback, {args.messages} messages, main thread polling every {args.poll * 1e3:g} ms")
    for r in latency:
        print(f"  {r['executor']:34s} median {r['median_ms']:8.3f} ms  p95 {r['p95_ms']:8.3f} ms  "
              f"max {r['max_ms']:8.1f} ms  CPU {r['cpu_s']:6.2f} s")
    if replay:
        print(f"lock-step replay, bags/temi_dynamic_pack1, first {args.replay_minutes:g} min")
        for r in replay:
            print(f"  {r['executor']:34s} {r['steps']} steps in {r['wall_s']:7.2f} s = {r['ms_per_step']:7.1f} ms per step")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
