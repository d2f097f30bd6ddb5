"""ROS messages <-> the engine's plain values. Imports message classes only, never rclpy.

* :mod:`msg_bridge.markers`: ``visualization_msgs/MarkerArray`` <-> Scene; predictions as markers.
* :mod:`msg_bridge.json_text`: ``std_msgs/String`` JSON <-> Scene and answers.
* :mod:`msg_bridge.outputs`: Float64, Vector3Stamped and DiagnosticArray from answers and stats.
* :mod:`msg_bridge.stamps`: nanosecond stamps <-> ``std_msgs/Header``.
* :mod:`msg_bridge.depth`: depth ``sensor_msgs/Image`` <-> metres, ``CameraInfo`` and the camera's ``PoseStamped``.

Every conversion is a pure function; bad input raises ``ValueError`` (``SceneError``) naming the field.
"""
