"""Pictures of scenes and answers: the colour palette (shared with the RViz markers) and rerun recordings.

``palette`` imports nothing but the standard library; ``rerun_log`` (predictions and questions) and
``perception_log`` (what vision and depth perception saw) are the only modules that import rerun, and
are imported only when recording is on. Never ROS.
"""
