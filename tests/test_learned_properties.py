"""What the node learned from observed motion, used in the scenes that follow (service/observations.py)."""

from __future__ import annotations

from ipe_ros.engine.scene.bodies import Box, Floor, Scene
from ipe_ros.service.observations import LearnedProperties


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def scene() -> Scene:
    box = Box("box", (0.1, 0.1, 0.1), (0, 0, 0.05), (0, 0, 0, 1), 0.9, 0.1, density_kg_m3=300.0)
    wall = Box("box_wall", (0.1, 1, 0.3), (1, 0, 0.15), (0, 0, 0, 1), 0.5, 0.0, static=True)
    return Scene("again", (box, wall), Floor(friction=1.0, restitution=0.0))


def test_learned_values_replace_an_objects_own_until_they_expire():
    clock = Clock()
    learned = LearnedProperties(keep_s=60.0, clock=clock)
    learned.learn({("box", "mass_kg"): 0.8, ("box", "friction"): 0.45, ("support", "friction"): 0.7})
    applied, used = learned.apply(scene())
    box = applied.objects[0]
    assert (box.mass_kg, box.density_kg_m3, box.friction, box.restitution) == (0.8, None, 0.45, 0.1)
    assert applied.support.friction == 0.7 and applied.objects[1] == scene().objects[1]
    assert used == (("support", "friction", 0.7), ("box", "friction", 0.45), ("box", "mass_kg", 0.8))
    clock.now += 61.0
    assert learned.apply(scene()) == (scene(), ())


def test_nothing_is_applied_when_keeping_is_off():
    learned = LearnedProperties(keep_s=0.0)
    learned.learn({("box", "friction"): 0.45})
    assert learned.apply(scene()) == (scene(), ())
