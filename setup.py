"""ament_python package friction_ros (also pip-installable for the venv set-up)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "friction_ros"

# Console scripts: ROS nodes (ros2 run friction_ros <name>) and user CLIs.
ENTRY_POINTS = [
    "drive_interface = friction_ros.nodes.drive_interface:main",
    "drive_emulator = friction_ros.nodes.drive_emulator:main",
    "friction-doctor = friction_ros.cli.doctor:main",
    "plant_simulator = friction_ros.nodes.plant_simulator:main",
    "compensating_controller = friction_ros.nodes.compensating_controller:main",
    "friction_estimator = friction_ros.nodes.friction_estimator:main",
    "simulated_drive = friction_ros.nodes.simulated_drive:main",
    "friction-bringup = friction_ros.cli.bringup:main",
    "friction-demo = friction_ros.cli.demo:main",
    "bag_recorder = friction_ros.nodes.bag_recorder:main",
    "bag_player = friction_ros.nodes.bag_player:main",
    "friction-bag = friction_ros.cli.bag:main",
    "friction-fit = friction_ros.cli.fit:main",
    "friction-fleet = friction_ros.cli.fleet:main",
    "identification_experiment = friction_ros.nodes.identification_experiment:main",
    "friction-experiment = friction_ros.cli.experiment:main",
]

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
    package_data={f"{PACKAGE}.nodes": ["fastdds_writer_profile.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/params", glob("params/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="friction_ros maintainers",
    maintainer_email="maintainers@friction-ros.org",
    description="Friction identification and compensation for geared servo joints (ROS 2 Jazzy).",
    license="Apache-2.0",
    entry_points={
        "console_scripts": ENTRY_POINTS,
        # python-can interface "friction_local": a CAN bus between processes without SocketCAN
        "can.interface": ["friction_local = friction_ros.can_bus.local_bus:LocalBus"],
    },
)
