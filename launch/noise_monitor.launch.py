"""Launch the noise monitor node for one camera (needs a full ROS 2 install with launch_ros).

    ros2 launch noise_monitor noise_monitor.launch.py namespace:=cam1 params_file:=my_camera.yaml image:=image_raw

Arguments:
  namespace:=NS        the camera's namespace: the node subscribes to NS/image, NS/metadata, NS/camera_info,
                       NS/temperature, publishes NS/noise_monitor/{frame,sigma_*,xi*,...} and names its
                       /diagnostics status "noise_monitor: NS" (unless camera_name is set); default: none
  params_file:=PATH    node parameters (default: the installed config/node.yaml; copy and edit it for your camera)
  image:=NAME, metadata:=NAME, camera_info:=NAME, temperature:=NAME
                       remap the relative input topics to the driver's names (e.g. image:=image_raw)
  log_level:=LEVEL     ROS log level (info)
"""
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from launch import LaunchDescription

#: The node's relative input topics (config/node.yaml defaults), each remappable by a launch argument.
INPUTS = ("image", "metadata", "camera_info", "temperature")


def generate_launch_description() -> LaunchDescription:
    default_params = PathJoinSubstitution([FindPackageShare("noise_monitor"), "config", "node.yaml"])
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="", description="the camera's namespace (e.g. cam1)"),
        DeclareLaunchArgument("params_file", default_value=default_params,
                              description="noise_monitor parameters (ROS params YAML)"),
        *[DeclareLaunchArgument(name, default_value=name, description=f"the camera's {name} topic (relative "
                                "names resolve in the namespace)") for name in INPUTS],
        DeclareLaunchArgument("log_level", default_value="info", description="ROS log level"),
        Node(
            package="noise_monitor",
            executable="noise_monitor_node",
            name="noise_monitor",
            namespace=LaunchConfiguration("namespace"),
            parameters=[LaunchConfiguration("params_file")],
            remappings=[(name, LaunchConfiguration(name)) for name in INPUTS],
            arguments=["--ros-args", "--log-level", LaunchConfiguration("log_level")],
            output="screen",
            emulate_tty=True,
        ),
    ])
