"""rclpy nodes: thin adapters over friction_ros.core."""

from friction_ros.nodes.stopping import install_early as _install_early

_install_early()  # a node process exits at once on SIGINT/SIGTERM while it imports its modules
