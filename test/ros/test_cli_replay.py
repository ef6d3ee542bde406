"""``battery-predictor replay``: a bag in, the nodes' outputs as an MCAP bag that rosbags opens, and a PNG.

Runs the real command in a subprocess (own ROS domain) on a short synthetic
relay-style bag (a 2 h constant-load discharge simulated with the fast model),
then reads the output bag with ``rosbags``' AnyReader, which decodes the
messages from the definitions embedded in the bag (as Foxglove does).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import Float64

from battery_predictor.io.bags import write_recording_bag
from battery_predictor.recording import Recording

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
CLI = Path(sys.executable).parent / "battery-predictor"


@pytest.fixture(scope="module")
def short_bag(tmp_path_factory) -> Path:
    """40 min at 5 s of a relay recording, and a made-up runtime truth."""
    t = np.arange(0.0, 2400.0, 5.0)
    v = 15.6 - 0.4 * t / 2400.0
    i = np.where((t // 300) % 2 == 0, 1.5, 3.0)
    temp = np.full(t.size, 297.0)
    path = tmp_path_factory.mktemp("bags") / "short_relay"
    write_recording_bag(Recording(t, v, i, temp), path, style="relay",
                        metadata={"truth": {"stop_voltage_v": 13.3, "runtime_s": 6 * 3600.0}})
    return path


def test_replay_writes_a_readable_output_bag_and_a_plot(short_bag: Path, tmp_path: Path, ros_domain_id: int) -> None:
    out = tmp_path / "replay"
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    argv = [str(CLI), "replay", str(short_bag), "--params", str(REPO / "params/ros/temi_nodes.yaml"),
            "--rate", "0", "--runtime-period", "300", "--out", str(out), "--json"]
    proc = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    # the replay ends one window after the last sample, so the last window is closed too
    assert summary["messages"] == 3 * 480 and summary["pack_states"] == 480
    assert summary["runtime_messages"] == 9  # at t = 0 (no state yet), 300, ..., 2400 s
    assert summary["valid_runtime_messages"] == 8
    assert [c["checkpoint_min"] for c in summary["checkpoints"]] == [30.0]
    png = Path(summary["plot"])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    from rosbags.highlevel import AnyReader

    counts: dict[str, int] = {}
    runtimes = []
    with AnyReader([Path(summary["output_bag"])]) as reader:
        for conn, t_ns, raw in reader.messages():
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.msgtype.endswith("RemainingRuntime"):
                runtimes.append((t_ns, msg))
            if conn.msgtype.endswith("PackState"):
                assert 15.0 < msg.voltage_v < 15.7 and msg.current_a in (1.5, 3.0) and not msg.stale
    assert counts["/pack_state"] == 480 and counts["/remaining_runtime"] == 9
    # the monitor's 1 s tick fires once per clock step (5 s apart in this bag), the predictor once per update
    assert counts["/diagnostics"] >= 480 + 9
    # log time = header stamp, on the bag's time base (use_sim_time): the first runtime at the bag start
    # (no state yet: stamped "now"), the others at the end of the 5 s window they are based on
    start_ns = 1_704_067_200 * 10**9
    assert runtimes[0][0] == start_ns
    assert [t for t, _ in runtimes[1:-1]] == [start_ns + k * 300 * 10**9 - 5 * 10**9 for k in range(1, 8)]
    assert runtimes[-1][0] >= start_ns + 2395 * 10**9
    assert not runtimes[0][1].valid and runtimes[0][1].status == 2  # STATUS_NO_INPUT
    assert all(m.valid and m.remaining_s > 0 for _, m in runtimes[1:])


def test_replay_refuses_a_pack_params_file_and_an_existing_output(short_bag: Path, tmp_path: Path) -> None:
    proc = subprocess.run([str(CLI), "replay", str(short_bag), "--params", str(REPO / "params/temi.yaml")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "pack params file" in proc.stderr and "Traceback" not in proc.stderr
    (tmp_path / "o" / "outputs").mkdir(parents=True)
    (tmp_path / "o" / "outputs" / "keep.txt").write_text("x")
    proc = subprocess.run([str(CLI), "replay", str(short_bag), "--params", str(REPO / "params/ros/temi_nodes.yaml"),
                           "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "exists" in proc.stderr
    assert (tmp_path / "o" / "outputs" / "keep.txt").exists()


def test_replay_of_a_bag_in_the_other_input_style_says_how_to_fix_it(tmp_path: Path) -> None:
    t = np.arange(0.0, 600.0, 5.0)
    bag = tmp_path / "battery_state_bag"
    write_recording_bag(Recording(t, 15.6 - 1e-4 * t, np.full(t.size, 1.5), np.full(t.size, 297.0)), bag,
                        style="battery_state")
    proc = subprocess.run([str(CLI), "replay", str(bag), "--params", str(REPO / "params/ros/temi_nodes.yaml"),
                           "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert "input_style: battery_state" in proc.stderr and "--style relay" in proc.stderr


@pytest.fixture(scope="module")
def measured_bag(tmp_path_factory) -> Path:
    """40 min at 5 s of a relay recording that reaches the temi cut-off (13.30 V) and has no truth metadata."""
    t = np.arange(0.0, 2400.0, 5.0)
    v = 15.6 - 2.5 * t / 2400.0  # 13.30 V at 2208 s
    i = np.where((t // 300) % 2 == 0, 1.5, 3.0)
    path = tmp_path_factory.mktemp("bags") / "measured_relay"
    write_recording_bag(Recording(t, v, i, np.full(t.size, 297.0)), path, style="relay")
    return path


def test_replay_of_a_measured_bag_takes_its_truth_from_the_recording_and_ignores_other_publishers(
        measured_bag: Path, tmp_path: Path, ros_context, ros_domain_id: int) -> None:
    # a "robot" on the environment's domain, publishing another pack's voltage and current on the replay's topics
    node = rclpy.create_node("live_robot", context=ros_context)
    pubs = [node.create_publisher(Float64, f"/battery/{name}", 10) for name in ("voltage", "current")]
    node.create_timer(0.02, lambda: [pub.publish(Float64(data=12.0)) for pub in pubs])
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
        argv = [str(CLI), "replay", str(measured_bag), "--params", str(REPO / "params/ros/temi_nodes.yaml"),
                "--rate", "0", "--runtime-period", "300", "--out", str(tmp_path / "replay"), "--json"]
        proc = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=600)
    finally:
        executor.shutdown()
        node.destroy_node()
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    # the private domain: the live publisher's 12.0 V samples never reach the replay's monitor
    assert summary["pack_states"] == 480 and summary["rejected_samples"] == {}
    # the recording's own end: the first 5 s window at or below 13.30 V, checkpoints at 10..90 % of it
    assert summary["truth_source"] == "recording: cutoff_window"
    assert 2205 / 60 <= summary["truth_runtime_min"] <= 2215 / 60
    marks = [c["checkpoint_min"] for c in summary["checkpoints"]]
    assert marks and all(0 < m < summary["truth_runtime_min"] for m in marks)
    assert summary["errors"]["mae_min"] >= 0
