"""ament_python setup for noise_monitor (also pip-installable)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "noise_monitor"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "bench"]),
    package_data={PACKAGE: ["estimator/weights/*"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.xml") + glob("config/*.json")),
        (f"share/{PACKAGE}/config/cameras", glob("config/cameras/*.yaml")),
        (f"share/{PACKAGE}/config/datasheets", glob("config/datasheets/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.py")),
        (f"share/{PACKAGE}/bags", glob("bags/**/*", recursive=True)),
    ],
    python_requires=">=3.10",
    # what `noise-monitor` (replay, analyze, simulate-bag, effects) and the estimator need; exact pins of
    # the tested set are in requirements.txt (use it as constraints: pip install . -c requirements.txt)
    install_requires=[
        "numpy>=1.26", "scipy>=1.11", "PyYAML>=6.0", "opencv-python-headless>=4.8", "torch>=2.2", "onnx>=1.15",
        "onnxruntime>=1.17", "rosbags>=0.10", "tqdm>=4.60", "matplotlib>=3.7",
        "cachetools>=5.0",
    ],
    extras_require={
        # the live node and `play` without a system ROS: ROS 2 Jazzy from PyPI wheels
        "ros": ["ros-jazzy-rclpy[fastrtps]>=7.1", "ros-jazzy-common-interfaces>=5.3"],
        # estimator training and evaluation data (scikit-image / PyWavelets sample images)
        "train": ["scikit-image>=0.22", "PyWavelets>=1.5"],
        # `noise-monitor campaign`: Ray tasks (optional: a local process pool otherwise) and Parquet tables
        "fleet": ["ray>=2.58", "pyarrow>=25"],
        # `--foxglove PORT` on `node` and `replay`: a live view over the Foxglove WebSocket protocol
        "live": ["foxglove-sdk>=0.30"],
        "dev": ["pytest>=8", "pytest-xdist>=3.5", "hypothesis>=6", "mcap>=1.1", "ruff>=0.15", "mypy>=1.10", "types-PyYAML", "build>=1.0", "websockets>=13"],
    },
    zip_safe=True,
    maintainer="noise_monitor developers",
    maintainer_email="dev@noise-monitor.invalid",
    description="Online camera noise source estimation and diagnosis for ROS 2",
    license="MIT",
    entry_points={
        "console_scripts": [
            "noise-monitor = noise_monitor.cli:main",
            "noise_monitor_node = noise_monitor.node:main",
        ],
    },
)
