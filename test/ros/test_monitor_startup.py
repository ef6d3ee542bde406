"""battery_monitor start-up: misspelled parameters and a range that misses the pack stop it; parameters are read-only.

The node is built as ``battery_monitor`` builds it (real rclpy node, own context and domain); the
console script is run once as a user would, to see the one-line error and exit code 2.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from rclpy.context import Context
from rclpy.parameter import Parameter

from battery_predictor.errors import ParamsError
from battery_predictor.nodes.battery_monitor_node import BatteryMonitorNode

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
RANGER_NODES = REPO / "params" / "ros" / "ranger_nodes.yaml"
TEMI_NODES = REPO / "params" / "ros" / "temi_nodes.yaml"
VENV_BIN = Path(sys.executable).parent


def _monitor(context: Context, node_params: Path, **overrides) -> BatteryMonitorNode:
    return BatteryMonitorNode(context=context, cli_args=["--ros-args", "--params-file", str(node_params)],
                              parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])


def test_misspelled_parameter_stops_the_monitor_and_names_the_declared_one(ros_context: Context) -> None:
    with pytest.raises(ParamsError, match=r"unknown parameter 'max_voltge_v' \(did you mean 'max_voltage_v'\?\)"):
        _monitor(ros_context, TEMI_NODES, max_voltge_v=17.0)


def test_range_that_misses_the_pack_stops_the_monitor(ros_context: Context) -> None:
    with pytest.raises(ParamsError, match=r"37.5..58 V does not cover the voltage window 12..16.4 V"):
        _monitor(ros_context, RANGER_NODES, params_file="temi.yaml")


def test_range_that_covers_the_pack_starts_and_publishes_ok(ros_context: Context) -> None:
    node = _monitor(ros_context, TEMI_NODES, params_file="temi.yaml")
    try:
        status = node.diagnostics(0.0).status[0]
        assert status.name.endswith("battery input") and status.level != b"\x02"
    finally:
        node.destroy_node()


def test_parameter_service_changes_are_refused_not_ignored(ros_context: Context) -> None:
    node = _monitor(ros_context, TEMI_NODES)
    try:
        result = node.set_parameters([Parameter("max_voltage_v", value=60.0)])[0]
        assert not result.successful and "read-only" in result.reason
        assert node.get_parameter("max_voltage_v").value == 17.0
        assert node.config.max_voltage_v == 17.0
    finally:
        node.destroy_node()


def test_console_script_with_a_typo_exits_2_with_one_line(ros_domain_id: int) -> None:
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.run([str(VENV_BIN / "battery_monitor"), "--ros-args", "--params-file", str(TEMI_NODES),
                           "-p", "windw_s:=5.0"], capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert "unknown parameter 'windw_s' (did you mean 'window_s'?)" in lines[0]


def test_every_declared_parameter_of_both_nodes_is_read_only(ros_context: Context) -> None:
    from battery_predictor.nodes.predictor_node import PredictorNode

    nodes = [_monitor(ros_context, TEMI_NODES),
             PredictorNode(context=ros_context, cli_args=["--ros-args", "--params-file", str(TEMI_NODES)])]
    try:
        for node in nodes:
            names = [n for n in node._parameters if n != "use_sim_time"]  # noqa: SLF001 - rclpy has no accessor
            assert len(names) > 5
            writable = [n for n in names if not node.describe_parameter(n).read_only]
            assert writable == [], f"{node.get_name()}: {writable}"
    finally:
        for node in nodes:
            node.destroy_node()
