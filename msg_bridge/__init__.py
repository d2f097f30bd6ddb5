"""ROS message <-> engine value conversions (imports message classes only, never rclpy).

The converters (MarkerArray / std_msgs String <-> Scene, Prediction -> output messages) arrive with
the node (issue 3); this package exists now so the layout, setup.py and colcon see it from the start.
"""
