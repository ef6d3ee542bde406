"""ament_python-compatible setup for battery_predictor (works with colcon and pip)."""

from glob import glob

from setuptools import find_packages, setup

package_name = "battery_predictor"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    package_data={package_name: ["py.typed"]},  # PEP 561: the package's type hints are checked (mypy)
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/params", glob("params/*.yaml")),
        ("share/" + package_name + "/params/ros", glob("params/ros/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="battery_predictor maintainers",
    maintainer_email="maintainers@battery-predictor.org",
    description="Runtime and route-feasibility prediction for battery-powered service robots",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "battery-predictor = battery_predictor.cli.main:main",
            "battery_monitor = battery_predictor.nodes.battery_monitor_main:main",
            "predictor = battery_predictor.nodes.predictor_main:main",
        ],
    },
)
