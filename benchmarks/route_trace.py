"""Where the time of a ``/can_accept_route`` round trip goes, per call, through the real nodes (issue 18).

Starts ``battery_monitor`` and one or more traced predictors (``benchmarks/_route_trace_node.py``,
each with ``battery_predictor`` from its own ``PYTHONPATH``, so snapshots of two commits run side by
side under the same load) plus an empty ``CanAcceptRoute`` service (a fixed answer on the nodes'
executor: the floor of Fast DDS and rclpy for the same request), feeds ``sensor_msgs/BatteryState``
at 10 Hz as ``benchmarks/ros_latency.py`` does, and then calls the longest Ranger route (80 kg) on
every service in turn, in a shuffled order each round with a random pause between calls. Every
step is timestamped on one clock (``time.monotonic_ns``, shared by the processes of a machine):

client: ``send0`` call_async, ``send1`` it returned (request converted and written), ``done`` the
response's future completed (in the client's executor), ``main`` the calling thread woke;
server: ``ready`` the spinning thread saw the request, ``take0/take1`` a worker took it,
``cb0/cb1`` the callback, ``core0/core1`` ``PredictorCore.can_accept_route``, ``send0/sent`` the
response written.

Usage: PYTHONPATH=. .venv/bin/python benchmarks/route_trace.py [--variant NAME=PYTHONPATH ...] [--calls 200]
       [--runtime-period 1.0] [--max-gap 0.3] [--no-echo] [--json OUT.json]
(default: one variant ``this`` = this checkout.)
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import rclpy  # noqa: E402
from battery_predictor_msgs.srv import CanAcceptRoute  # noqa: E402
from rclpy.context import Context  # noqa: E402

from battery_predictor.nodes.executor import StartedMultiThreadedExecutor  # noqa: E402
from battery_predictor.nodes.messages import route_section_msgs  # noqa: E402
from battery_predictor.profiles.ranger import longest_route  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_latency import NODE_PARAMS, TIMEOUT_S, Bench, _wait, shut_down  # noqa: E402

BIN = Path(sys.executable).parent
HELPER = Path(__file__).resolve().parent / "_route_trace_node.py"

#: Segments reported (name, start key, end key, side of the start key, side of the end key).
SEGMENTS = [
    ("client: request converted and written", "c.send0", "c.send1"),
    ("middleware -> server's spinning thread woke", "c.send1", "s.ready"),
    ("spinning thread -> worker took the request", "s.ready", "s.take0"),
    ("take (deserialise the request)", "s.take0", "s.take1"),
    ("taken -> callback entered", "s.take1", "s.cb0"),
    ("callback before the core (request sections)", "s.cb0", "s.core0"),
    ("core: PredictorCore.can_accept_route", "s.core0", "s.core1"),
    ("  core before the calibration", "s.core0", "s.cal0"),
    ("  calibration (cached, or waits for the state's)", "s.cal0", "s.cal1"),
    ("  calibration -> route runs", "s.cal1", "s.eval0"),
    ("  route runs (evaluate_route_at_risk)", "s.eval0", "s.eval1"),
    ("  after the route runs", "s.eval1", "s.core1"),
    ("callback after the core (response, stats)", "s.core1", "s.cb1"),
    ("callback returned -> send_response", "s.cb1", "s.send0"),
    ("send_response (serialise, write)", "s.send0", "s.sent"),
    ("middleware -> client's future done", "s.sent", "c.done"),
    ("client's calling thread woke", "c.done", "c.main"),
    ("server side: ready -> sent", "s.ready", "s.sent"),
    ("callback (the node's own figure)", "s.cb0", "s.cb1"),
    ("outside the callback (round trip - callback)", None, None),
    ("round trip send0 -> main (ros_latency's figure)", "c.send0", "c.main"),
    ("round trip send0 -> done", "c.send0", "c.done"),
]


def _stats(values_ms: list[float]) -> dict[str, float]:
    a = np.asarray(values_ms, dtype=float)
    if a.size == 0:
        return {"n": 0}
    return {"n": int(a.size), "p50_ms": float(np.percentile(a, 50)), "p95_ms": float(np.percentile(a, 95)),
            "max_ms": float(a.max())}


def _segments(client: list[dict], server: list[dict]) -> dict[str, dict[str, float]]:
    out: dict[str, list[float]] = {name: [] for name, *_ in SEGMENTS}
    for c, s in zip(client, server):
        keys = {f"c.{k}": v for k, v in c.items()} | {f"s.{k}": v for k, v in s.items()}
        for name, a, b in SEGMENTS:
            if a is None:
                if "s.cb0" in keys and "s.cb1" in keys:
                    out[name].append((keys["c.main"] - keys["c.send0"] - keys["s.cb1"] + keys["s.cb0"]) / 1e6)
                continue
            if keys.get(a) and keys.get(b):
                out[name].append((keys[b] - keys[a]) / 1e6)
    return {name: _stats(v) for name, v in out.items()}


def _overlaps(server: list[dict], busy: dict[str, list]) -> dict[str, dict]:
    """Per kind of the node's other model work: how many callbacks overlapped it, and their core time."""
    out = {}
    for kind, intervals in busy.items():
        hit, miss = [], []
        for s in server:
            if "core0" not in s:
                continue
            a, b = s["cb0"], s["cb1"]
            overlapped = any(t0 < b and t1 > a for t0, t1 in intervals)
            (hit if overlapped else miss).append((s["core1"] - s["core0"]) / 1e6)
        durations = [(t1 - t0) / 1e6 for t0, t1 in intervals]
        out[kind] = {"count": len(intervals), "duration": _stats(durations), "calls_overlapping": len(hit),
                     "core_when_overlapping": _stats(hit), "core_otherwise": _stats(miss)}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variant", action="append", default=[],
                    help="NAME=PYTHONPATH of a predictor to trace (repeatable; default this=<this checkout>)")
    ap.add_argument("--calls", type=int, default=200, help="calls per service (default 200)")
    ap.add_argument("--payload", type=float, default=80.0)
    ap.add_argument("--runtime-period", type=float, default=1.0, help="predictor.runtime_period_s (default 1.0)")
    ap.add_argument("--max-gap", type=float, default=0.3, help="random pause after each call, 0..this s")
    ap.add_argument("--no-echo", action="store_true", help="without the empty service")
    ap.add_argument("--predictor-arg", action="append", default=[],
                    help="extra predictor parameter, e.g. route_priority:=false (repeatable)")
    ap.add_argument("--json", default="", help="write the full result here")
    args = ap.parse_args()
    variants = [v.split("=", 1) for v in args.variant] or [["this", str(REPO)]]

    domain = random.randrange(150, 230)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_LOCALHOST_ONLY", None)
    os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    tmp = Path(tempfile.mkdtemp(prefix="route_trace_"))
    common = ["--ros-args", "--params-file", str(NODE_PARAMS), "--log-level", "warn"]
    procs = [subprocess.Popen([str(BIN / "battery_monitor"), *common], env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True)]
    targets: list[tuple[str, str, Path]] = []
    for name, path in variants:
        service = f"/{name}/can_accept_route"
        trace = tmp / f"{name}.json"
        extra = [x for p in args.predictor_arg for x in ("-p", f"predictor:{p}")]
        procs.append(subprocess.Popen(
            [sys.executable, str(HELPER), "predictor", str(trace), *common, "-p",
             f"predictor:runtime_period_s:={args.runtime_period}", "-p",
             f"predictor:can_accept_route_service:={service}", *extra],
            env=dict(env, PYTHONPATH=path), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True))
        targets.append((name, service, trace))
    if not args.no_echo:
        trace = tmp / "echo.json"
        procs.append(subprocess.Popen(
            [sys.executable, str(HELPER), "echo", str(trace), *common, "-r", "can_accept_route:=/echo/can_accept_route"],
            env=dict(env, PYTHONPATH=str(REPO)), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True))
        targets.append(("empty service", "/echo/can_accept_route", trace))

    context = Context()
    rclpy.init(args=[], context=context, domain_id=domain)
    bench = Bench(context, 49.0)
    clients = {name: bench.create_client(CanAcceptRoute, service) for name, service, _ in targets}
    executor = StartedMultiThreadedExecutor(num_threads=2, context=context)
    executor.add_node(bench)
    threading.Thread(target=executor.spin, daemon=True).start()
    request = CanAcceptRoute.Request(sections=route_section_msgs(longest_route(args.payload).sections))
    client_trace: dict[str, list[dict]] = {name: [] for name, *_ in targets}
    answers: dict[str, set] = {name: set() for name, *_ in targets}
    load = []
    try:
        for name, client in clients.items():
            _wait(client.service_is_ready, f"{name}", procs)
        _wait(lambda: len(bench.runtime_updates_s) >= 2 * len(variants), "the first valid runtime updates", procs)
        load.append(os.getloadavg())
        for k in range(args.calls + 1):
            order = list(clients.items())
            random.shuffle(order)
            for name, client in order:
                record: dict[str, int] = {}
                woke = threading.Event()

                def on_done(_f, r=record, e=woke) -> None:
                    r["done"] = time.monotonic_ns()
                    e.set()
                record["send0"] = time.monotonic_ns()
                future = client.call_async(request)
                record["send1"] = time.monotonic_ns()
                future.add_done_callback(on_done)
                if not woke.wait(TIMEOUT_S):
                    raise SystemExit(f"{name}: no response within the timeout")
                record["main"] = time.monotonic_ns()
                response = future.result()
                if k > 0:
                    answers[name].add((response.accepted, response.reason, response.predicted_voltage_v))
                client_trace[name].append(record)
                time.sleep(random.uniform(0.0, args.max_gap))
        load.append(os.getloadavg())
    finally:
        shut_down(executor, bench, context, procs)

    result: dict = {"calls": args.calls, "runtime_period_s": args.runtime_period, "load_before_after": load,
                    "variants": dict(variants), "targets": {}}
    for name, _service, trace in targets:
        data = json.loads(trace.read_text()) if trace.exists() else {"calls": [], "busy": {}}
        server, busy = data["calls"], data["busy"]
        client = client_trace[name]
        if len(server) != len(client):
            print(f"warning: {name}: {len(server)} server records for {len(client)} calls", file=sys.stderr)
        result["targets"][name] = {"segments": _segments(client[1:], server[1:]),
                                   "overlaps": _overlaps(server[1:], busy),
                                   "distinct_answers": len(answers[name]),
                                   "answer": [list(a) for a in sorted(answers[name])][:3],
                                   "raw": {"client": client, "server": server, "busy": busy}}
    if args.json:  # with every call's timestamps ("raw")
        Path(args.json).write_text(json.dumps(result))
    for data in result["targets"].values():
        del data["raw"]
    print(f"load average (1, 5, 15 min) before {load[0]}, after {load[-1] if len(load) > 1 else '?'}")
    for name, data in result["targets"].items():
        print(f"\n{name} ({variants and dict(variants).get(name, '')}): {data['distinct_answers']} distinct answer(s)")
        for seg, st in data["segments"].items():
            if st.get("n"):
                print(f"  {seg:<50} p50 {st['p50_ms']:7.3f}  p95 {st['p95_ms']:7.3f}  max {st['max_ms']:8.3f} ms")
        for kind, o in data["overlaps"].items():
            d, h, m = o["duration"], o["core_when_overlapping"], o["core_otherwise"]
            line = f"  {kind}: {o['count']} runs"
            if d.get("n"):
                line += f" (p50 {d['p50_ms']:.2f}, max {d['max_ms']:.2f} ms)"
            line += f"; {o['calls_overlapping']} callbacks overlapped one"
            if h.get("n"):
                line += f" (core p50 {h['p50_ms']:.2f} / p95 {h['p95_ms']:.2f} ms)"
            if m.get("n"):
                line += f", the others core p50 {m['p50_ms']:.2f} / p95 {m['p95_ms']:.2f} ms"
            print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
