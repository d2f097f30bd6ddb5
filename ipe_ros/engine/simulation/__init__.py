"""The simulation of one rollout with pybullet, in parts (see stepper.py for how they fit).

world.py builds and reads pybullet worlds; depenetration.py separates overlapping boxes; stepper.py
runs the loop that settling.py, collapse.py, termination.py and health.py each take part in;
islands.py tells which bodies can be simulated apart; probe.py lets a benchmark watch the parts.
"""

from . import islands
from .depenetration import depenetrate, set_down
from .islands import IslandsMet
from .probe import NO_PROBE, PHASES, Probe
from .stepper import Push, RolloutEnd, begin, simulate
from .termination import DecidedHeights
from .bullet import client, pybullet
from .world import (World, build_world, combined_restitution, in_plain_rigid_bodies, read_poses, read_velocities,
                    time_step_of, uses_direct_solver)

__all__ = ["NO_PROBE", "PHASES", "DecidedHeights", "IslandsMet", "Probe", "Push", "RolloutEnd", "World", "begin",
           "build_world", "client", "combined_restitution", "depenetrate", "in_plain_rigid_bodies", "pybullet",
           "read_poses", "read_velocities", "set_down", "simulate", "time_step_of", "uses_direct_solver"]
