"""The ROS 2 layer: the node, its parameters, the demo and ``ipe_send_scene``.

The only modules of the package that import rclpy (a test checks it). They convert messages with
``msg_bridge`` and leave all the work to :class:`ipe_ros.service.PredictionService`.
"""
