"""Pure core of friction_ros: no rclpy imports anywhere below this package."""
