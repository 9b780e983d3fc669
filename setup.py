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
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.xml")),
        (f"share/{PACKAGE}/config/cameras", glob("config/cameras/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.py")),
        (f"share/{PACKAGE}/bags", glob("bags/**/*", recursive=True)),
    ],
    install_requires=["setuptools", "numpy", "scipy", "pyyaml"],
    zip_safe=True,
    maintainer="noise_monitor developers",
    maintainer_email="dev@noise-monitor.invalid",
    description="Online camera noise source estimation and diagnosis for ROS 2",
    license="MIT",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "noise-monitor = noise_monitor.cli:main",
            "noise_monitor_node = noise_monitor.node:main",
        ],
    },
)
