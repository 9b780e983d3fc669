"""Launch the noise monitor node (for users with a full ROS 2 install: ros2 launch noise_monitor noise_monitor.launch.py).

Arguments:
  params_file:=PATH   node parameters (default: the installed config/node.yaml; copy and edit it for your camera)
  namespace:=NS       namespace of the node (its numeric topics are <namespace>/noise_monitor/<name>)
  log_level:=LEVEL    ROS log level (info)
Input topics are parameters (image_topic, metadata_topic, ...); remap them here or set them in the params file.
"""
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    default_params = PathJoinSubstitution([FindPackageShare("noise_monitor"), "config", "node.yaml"])
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=default_params,
                              description="noise_monitor parameters (ROS params YAML)"),
        DeclareLaunchArgument("namespace", default_value="", description="namespace of the node"),
        DeclareLaunchArgument("log_level", default_value="info", description="ROS log level"),
        Node(
            package="noise_monitor",
            executable="noise_monitor_node",
            name="noise_monitor",
            namespace=LaunchConfiguration("namespace"),
            parameters=[LaunchConfiguration("params_file")],
            arguments=["--ros-args", "--log-level", LaunchConfiguration("log_level")],
            output="screen",
            emulate_tty=True,
        ),
    ])
