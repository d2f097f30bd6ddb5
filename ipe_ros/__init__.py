"""ipe_ros: the intuitive physics engine (Battaglia, Hamrick & Tenenbaum 2013) as a ROS 2 service.

Layers, imports pointing down only (tests/test_layers.py checks them):

    ipe_ros.ros        the node, its parameters, the demo, ipe_send_scene: the only rclpy users
    msg_bridge         ROS message classes <-> engine values (never rclpy, never the service)
    ipe_ros.service    prediction as a service without ROS: keep-latest queue, thread, worker pool
    ipe_ros.cli        the ``ipe`` command line
    ipe_ros.analysis   the paper's analyses (``ipe experiment``) and its data (paper_data)
    ipe_ros.viz        colours and rerun recordings
    ipe_ros.engine     the IPE itself: numpy + pybullet, never ROS
"""

__version__ = "0.1.0"
