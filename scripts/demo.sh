#!/usr/bin/env bash
# The main job on a built-in example: set up .venv (pinned), then run the ROS 2 node on a paper tower
# (published as a MarkerArray by a built-in robot node), print the answers, write .rrd recordings
# to ./ipe_demo_output, and end by itself. Extra arguments go to ipe_ros_demo (see --help).
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh"
cd "$ROOT"
# A domain of its own, so the demo neither hears nor disturbs other ROS 2 programs on this machine.
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 100) + 100 ))}"
exec ipe_ros_demo "$@"
