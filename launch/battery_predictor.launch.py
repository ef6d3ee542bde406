"""Launch the battery monitor and the predictor (for a full ROS 2 Jazzy install with launch_ros).

    ros2 launch battery_predictor battery_predictor.launch.py robot:=temi
    ros2 launch battery_predictor battery_predictor.launch.py robot:=ranger
    ros2 launch battery_predictor battery_predictor.launch.py params_file:=/path/to/my_nodes.yaml use_sim_time:=true

``robot`` picks the bundled node parameters ``share/battery_predictor/params/ros/<robot>_nodes.yaml``
(``battery_monitor:`` / ``predictor:`` ``ros__parameters``); ``params_file`` replaces them.
Without a ROS install (pip wheels), use ``battery-predictor run --params P.yaml`` instead:
it starts the same two nodes in one process.
"""

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory("battery_predictor")
    robot = LaunchConfiguration("robot")
    params_file = LaunchConfiguration("params_file")
    use_sim_time = ParameterValue(LaunchConfiguration("use_sim_time"), value_type=bool)
    log_level = LaunchConfiguration("log_level")

    def node(executable: str) -> Node:
        return Node(
            package="battery_predictor",
            executable=executable,
            name=executable,
            parameters=[params_file, {"use_sim_time": use_sim_time}],
            arguments=["--ros-args", "--log-level", log_level],
            output="screen",
            emulate_tty=True,
        )

    return LaunchDescription([
        DeclareLaunchArgument("robot", default_value="temi", choices=["temi", "ranger"],
                              description="Robot whose bundled node parameters to use."),
        DeclareLaunchArgument(
            "params_file",
            default_value=PathJoinSubstitution([share, "params", "ros", [robot, "_nodes.yaml"]]),
            description="Node parameters file (battery_monitor: / predictor: ros__parameters)."),
        DeclareLaunchArgument("use_sim_time", default_value="false", choices=["true", "false"],
                              description="Follow /clock (set true while a bag is played with --clock)."),
        DeclareLaunchArgument("log_level", default_value="info", description="Log level of both nodes."),
        node("battery_monitor"),
        node("predictor"),
    ])
