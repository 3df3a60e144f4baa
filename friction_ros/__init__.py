"""friction_ros: friction identification and compensation for geared servo joints.

``friction_ros.core`` is the pure core (models, plant, controllers, estimators, identification,
CAN codecs, bag I/O); it never imports rclpy. ``friction_ros.nodes`` holds the thin rclpy adapters.
"""

__version__ = "0.1.0"
