"""ipe_ros: the intuitive physics engine (Battaglia, Hamrick & Tenenbaum 2013) as a ROS 2 service.

This top-level package imports nothing from ROS: the engine lives in :mod:`ipe_ros.engine` and runs
without rclpy; only :mod:`ipe_ros.node` imports rclpy.
"""

__version__ = "0.1.0"
