"""A scene's known pushes after t = 0 (``Scene.pushes``: an observation's actions) as the rollout
applies them: each body's velocity changed at the first step boundary at or after its time."""

from __future__ import annotations

import math

import numpy as np

from ..scene.bodies import Scene
from .bullet import pybullet
from .world import World


class Kicks:
    """The pushes still to come, as (tick, body handle, velocity change) in time order; a push on a
    body not in this world (another island's) is left to that world."""

    def __init__(self, scene: Scene, world: World, dt: float):
        handles = {body.name: handle for handle, body in zip(world.dynamic_ids, scene.dynamic_objects)} \
            if scene.pushes else {}  # every rollout makes one: nothing to look up in the usual case
        self.world = world
        self.due = sorted(((int(math.ceil(push.at_s / dt - 1e-9)), handles[push.name],
                            np.asarray(push.velocity_change_m_s, float))
                           for push in scene.pushes if push.name in handles), key=lambda kick: kick[0])
        #: the most speed they can add to a body: every push's together
        self.speed_m_s = sum(float(np.linalg.norm(change)) for _, _, change in self.due)
        #: the tick of the last (0: none), before which the rollout cannot be at rest
        self.last_tick = self.due[-1][0] if self.due else 0

    def apply(self, tick: int) -> bool:
        """Change the velocities of the pushes due by ``tick``; whether any was."""
        if not self.due or self.due[0][0] > tick:
            return False
        p, cid = pybullet(), self.world.client
        while self.due and self.due[0][0] <= tick:
            _, handle, change = self.due.pop(0)
            linear, angular = p.getBaseVelocity(handle, physicsClientId=cid)
            p.resetBaseVelocity(handle, (np.asarray(linear) + change).tolist(), angular, physicsClientId=cid)
        return True
