"""What the node learned from observed motion, used in the scenes that follow (service/observations.py)."""

from __future__ import annotations

from ipe_ros.engine.scene.bodies import Box, Floor, Scene
from ipe_ros.engine.scene.properties import LogNormal, Uniform
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
    assert used == (("box", "friction", 0.45), ("box", "mass_kg", 0.8), ("support", "friction", 0.7))
    assert box.priors == () and applied.support.priors == ()  # learned without a posterior's width: exact
    clock.now += 61.0
    assert learned.apply(scene()) == (scene(), ())


def test_nothing_is_applied_when_keeping_is_off():
    learned = LearnedProperties(keep_s=0.0)
    learned.learn({("box", "friction"): 0.45})
    assert learned.apply(scene()) == (scene(), ())


def test_the_posterior_rides_along_as_the_properties_prior():
    # a later prediction draws what is still uncertain (and names it), instead of trusting the median
    learned = LearnedProperties(keep_s=60.0)
    learned.learn({("box", "friction"): 0.45, ("box", "restitution"): 0.3, ("box_wall", "friction"): 0.2},
                  {("box", "friction"): LogNormal(0.45, 0.1), ("box", "restitution"): Uniform(0.2, 0.4)})
    applied, used = learned.apply(scene())
    assert dict(applied.objects[0].priors) == {"friction": LogNormal(0.45, 0.1), "restitution": Uniform(0.2, 0.4)}
    assert applied.objects[1] == scene().objects[1]  # a static object is never changed
    assert [u[:2] for u in used] == [("box", "friction"), ("box", "restitution")]
