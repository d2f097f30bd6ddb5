"""Pictures of scenes and answers: the colour palette (shared with the RViz markers) and rerun recordings.

``palette`` imports nothing but the standard library; ``rerun_log`` is the only module that imports
rerun, and is imported only when recording is on. Never ROS.
"""
