"""Node parameters: params/ros/*.yaml load into the real nodes; descriptors; console scripts and ``run``.

The YAML files are read by rcl itself (``--ros-args --params-file``), as
``ros2 run`` / ``ros2 launch`` would; every key in them must be a parameter the
node declares (a typo would otherwise be ignored silently).
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from battery_predictor_msgs.srv import CanAcceptRoute
from rclpy.context import Context
from rclpy.exceptions import InvalidParameterValueException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from battery_predictor.cli.cmd_run import ros_arguments
from battery_predictor.errors import ParamsError
from battery_predictor.nodes._params import undeclared_overrides
from battery_predictor.nodes.battery_monitor_node import BatteryMonitorNode
from battery_predictor.nodes.messages import route_section_msgs
from battery_predictor.nodes.predictor_node import PredictorNode
from battery_predictor.nodes.predictor_parameters import PREDICTOR_PARAMETERS
from battery_predictor.prediction.core import PredictorConfig
from battery_predictor.profiles.ranger import longest_route

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
NODE_PARAMS = sorted((REPO / "params" / "ros").glob("*_nodes.yaml"))
VENV_BIN = Path(sys.executable).parent
TIMEOUT_S = 90.0


def test_there_are_node_params_for_both_robots() -> None:
    assert {"ranger_nodes.yaml", "temi_nodes.yaml"} <= {p.name for p in NODE_PARAMS}


@pytest.mark.parametrize("path", NODE_PARAMS, ids=lambda p: p.name)
def test_node_params_file_loads_into_the_nodes(path: Path, ros_context: Context) -> None:
    data = yaml.safe_load(path.read_text())
    assert set(data) == {"battery_monitor", "predictor"}
    cli = ["--ros-args", "--params-file", str(path)]
    monitor = BatteryMonitorNode(context=ros_context, cli_args=cli)
    predictor = PredictorNode(context=ros_context, cli_args=cli)
    try:
        for node, name in ((monitor, "battery_monitor"), (predictor, "predictor")):
            expected = data[name]["ros__parameters"]
            assert undeclared_overrides(node) == [], f"{path.name}: {name} ignores these keys"
            for key, value in expected.items():
                got = node.get_parameter(key).value
                assert got == pytest.approx(value) if isinstance(value, float) else got == value, key
            for key in node._parameters:  # noqa: SLF001 - every declared parameter is documented
                if key == "use_sim_time":
                    continue
                descriptor = node.describe_parameter(key)
                assert descriptor.description, f"{name}.{key} has no description"
                if descriptor.type == Parameter.Type.DOUBLE.value:
                    assert descriptor.floating_point_range, f"{name}.{key} has no range"
        assert monitor.config.input_style == data["battery_monitor"]["ros__parameters"]["input_style"]
        assert predictor.core.runner is not None, predictor.core.model_error
        assert Path(predictor.core.params.source).name == data["predictor"]["ros__parameters"]["params_file"]
        # parameters -> the frozen configs the cores receive
        mon = data["battery_monitor"]["ros__parameters"]
        assert monitor.config.max_voltage_v == mon["max_voltage_v"]
        assert monitor.config.min_temperature_k == pytest.approx(mon["min_temperature_c"] + 273.15)
        assert math.isnan(predictor.config.cutoff_voltage_v)  # 0 in the file = from the pack params
        pack = predictor.core.params
        expected_cutoff_v = pack.thresholds.get("runtime_cutoff_voltage_v", pack.pack_info["min_voltage_v"])
        assert predictor.core.cutoff_voltage_v == pytest.approx(expected_cutoff_v)
        assert predictor.core.cutoff_voltage_v in (13.30, 45.00, 2.50, 18.00)  # the shipped packs' cut-offs
    finally:
        monitor.destroy_node()
        predictor.destroy_node()


def test_every_field_of_the_predictors_config_is_a_node_parameter_with_the_cores_default(ros_context: Context) -> None:
    assert [spec.name for spec in PREDICTOR_PARAMETERS] == list(dict.fromkeys(s.name for s in PREDICTOR_PARAMETERS))
    assert {spec.name for spec in PREDICTOR_PARAMETERS} == set(PredictorConfig.__dataclass_fields__)
    node = PredictorNode(context=ros_context, parameter_overrides=[Parameter("params_file", value="temi.yaml")])
    try:
        defaults = PredictorConfig(params_file=node.config.params_file)
        for name in PredictorConfig.__dataclass_fields__:  # 0 = "from the params file" is the core's NaN
            got, want = getattr(node.config, name), getattr(defaults, name)
            assert got == want or (math.isnan(got) and math.isnan(want)), name
    finally:
        node.destroy_node()


def test_out_of_range_parameter_is_refused(ros_context: Context) -> None:
    with pytest.raises(InvalidParameterValueException):
        BatteryMonitorNode(context=ros_context, parameter_overrides=[Parameter("window_s", value=-5.0)])
    with pytest.raises(ValueError, match="input_style"):
        BatteryMonitorNode(context=ros_context, parameter_overrides=[Parameter("input_style", value="can_bus")])


def test_missing_pack_params_stop_the_node_with_one_line(ros_context: Context) -> None:
    with pytest.raises(ParamsError, match="no usable pack model: .*nonexistent.yaml"):
        PredictorNode(context=ros_context, parameter_overrides=[Parameter("params_file", value="/nonexistent.yaml")])


def test_misspelled_parameter_or_a_cutoff_outside_the_pack_stop_the_predictor(ros_context: Context) -> None:
    with pytest.raises(ParamsError, match="did you mean 'cutoff_voltage_v'"):
        PredictorNode(context=ros_context, parameter_overrides=[Parameter("params_file", value="temi.yaml"),
                                                                Parameter("cutoff_voltag_v", value=13.3)])
    with pytest.raises(ParamsError, match="cutoff_voltage_v"):
        PredictorNode(context=ros_context, parameter_overrides=[Parameter("params_file", value="temi.yaml"),
                                                                Parameter("cutoff_voltage_v", value=133.0)])


def test_run_arguments_check_the_params_file(tmp_path: Path) -> None:
    fit = REPO / "docs" / "evaluation" / "ranger_fit_stepwise.yaml"
    args = ros_arguments(str(REPO / "params" / "ros" / "ranger_nodes.yaml"), pack=str(fit), use_sim_time=True)
    assert args[1:4] == ["--ros-args", "--params-file", str(REPO / "params" / "ros" / "ranger_nodes.yaml")]
    assert f"predictor:params_file:={fit}" in args and "use_sim_time:=true" in args
    with pytest.raises(ParamsError, match="'my_fit.yaml': pack params file not found"):
        ros_arguments(str(NODE_PARAMS[0]), pack="my_fit.yaml")
    with pytest.raises(ParamsError, match="pack params file"):
        ros_arguments(str(REPO / "params" / "temi.yaml"))
    bad = tmp_path / "bad.yaml"
    bad.write_text("predictor:\n  params_file: temi.yaml\n")
    with pytest.raises(ParamsError, match="ros__parameters"):
        ros_arguments(str(bad))


def _ros_env(domain_id: int) -> dict[str, str]:
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


def _wait_for_service_answer(ros_context: Context, name: str, proc: subprocess.Popen) -> CanAcceptRoute.Response:
    node = Node("params_test_client", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    try:
        client = node.create_client(CanAcceptRoute, name)
        deadline = time.monotonic() + TIMEOUT_S
        while not client.service_is_ready():
            assert proc.poll() is None, f"process exited early: {proc.communicate()[1][-2000:]}"
            assert time.monotonic() < deadline, "service did not appear"
            executor.spin_once(timeout_sec=0.1)
        future = client.call_async(CanAcceptRoute.Request(sections=route_section_msgs(longest_route(40).sections)))
        executor.spin_until_future_complete(future, timeout_sec=TIMEOUT_S)
        assert future.done()
        return future.result()
    finally:
        executor.shutdown()
        node.destroy_node()


def _stop(proc: subprocess.Popen) -> tuple[int, str]:
    proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
        pytest.fail(f"did not stop on SIGINT: {err[-2000:]}")
    return proc.returncode, err


@pytest.mark.parametrize("command", ["run", "predictor"])
def test_console_scripts_serve_and_stop_cleanly_on_ctrl_c(command: str, ros_context: Context,
                                                          ros_domain_id: int, unique_name: str) -> None:
    params = str(REPO / "params" / "ros" / "ranger_nodes.yaml")
    service = f"/{unique_name}/can_accept_route"
    remap = ["-p", f"predictor:can_accept_route_service:={service}"]
    if command == "run":
        argv = [str(VENV_BIN / "battery-predictor"), "run", "--params", params, "--ros-args", *remap]
    else:
        argv = [str(VENV_BIN / "predictor"), "--ros-args", "--params-file", params, *remap]
    proc = subprocess.Popen(argv, env=_ros_env(ros_domain_id), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        response = _wait_for_service_answer(ros_context, service, proc)
    finally:
        code, err = _stop(proc)
    assert not response.accepted and "state unknown" in response.reason  # no battery input in this test
    assert code == 0, err[-2000:]
    assert "Traceback" not in err
