"""rclpy nodes: thin adapters over friction_ros.core."""
