"""Observations made at known properties: the engine's own rollout at `paper` settings, read at a
tracker's frame rate, with its noise. For the tests (analytic cases), the docs' worked example and
``ipe generate probe-push``. Everything random comes from the ``Generator`` passed in.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..config import preset
from ..scene.bodies import Body, Box, Floor, Scene, TimedPush
from ..scene.format import scene_to_dict
from ..scene.shapes import Sphere
from .observation import OBSERVATION_FORMAT
from .likelihood import interpolate_positions
from .particle import body_paths, trajectory_sample

UPRIGHT = (0.0, 0.0, 0.0, 1.0)


def observe(scene: Scene, window_s: float, rng: np.random.Generator, *, unknowns: list, frame_rate_hz: float = 30.0,
            position_sd_m: float = 0.002, actions: list = (), velocity_unknown: tuple[str, ...] = (),
            settings: str = "paper") -> dict:
    """An ``ipe_ros.observation/1`` dict of ``scene`` rolled out at ``settings`` (with ``actions``'
    velocities already in the scene's initial state), each object's position read every
    1/frame_rate_hz s with N(0, position_sd_m^2) noise per axis. ``velocity_unknown``: objects whose
    initial velocity the observation leaves out."""
    outcome = trajectory_sample(dataclasses.replace(scene, horizon_s=window_s), preset(settings))
    if not outcome.ok:
        raise RuntimeError(f"the observed rollout failed: {outcome.error}")
    times, paths = body_paths(scene, outcome.rollouts[0].trajectory)
    frame_times = np.arange(1, int(np.floor(window_s * frame_rate_hz + 1e-9)) + 1) / frame_rate_hz
    frames = [{"t_s": round(float(t), 6), "objects": {}} for t in frame_times]
    for body in scene.dynamic_objects:
        seen = interpolate_positions(times, paths[body.name][0], frame_times)
        for frame, at in zip(frames, seen):
            noisy = at + position_sd_m * rng.standard_normal(3)
            frame["objects"][body.name] = {"position_m": [round(float(v), 6) for v in noisy]}
    scene_dict = scene_to_dict(scene)
    velocities = {b.name: b.linear_velocity_m_s for b in scene.objects}
    for item in scene_dict["objects"]:
        item.pop("linear_velocity_m_s", None)  # the writer leaves out a zero; the observation says it: at rest
        if item["name"] not in velocity_unknown and not item.get("static", False):
            item["linear_velocity_m_s"] = list(velocities[item["name"]])
    return {"format": OBSERVATION_FORMAT, "scene": scene_dict, "position_sd_m": position_sd_m, "frames": frames,
            "unknowns": list(unknowns), "actions": list(actions)}


def sliding_box(speed_m_s: float, friction: float, heading_rad: float = 0.0) -> Scene:
    """A 10 cm box sliding on a floor of friction 1 (so the pair's friction is the box's)."""
    v = (speed_m_s * np.cos(heading_rad), speed_m_s * np.sin(heading_rad), 0.0)
    box = Box("box", (0.1, 0.1, 0.1), (0.0, 0.0, 0.05), UPRIGHT, friction, 0.0, mass_kg=0.5,
              linear_velocity_m_s=tuple(float(c) for c in v))
    return Scene("sliding-box", (box,), Floor(friction=1.0, restitution=0.0))


def head_on(mass_a_kg: float, mass_b_kg: float, speed_m_s: float = 1.5, restitution: float = 0.5) -> Scene:
    """Box a slides into box b at rest, 30 cm ahead, on a nearly frictionless floor."""
    a = Box("a", (0.1, 0.1, 0.1), (0.0, 0.0, 0.05), UPRIGHT, 0.05, restitution, mass_kg=mass_a_kg,
            linear_velocity_m_s=(speed_m_s, 0.0, 0.0))
    b = Box("b", (0.1, 0.1, 0.1), (0.3, 0.0, 0.05), UPRIGHT, 0.05, restitution, mass_kg=mass_b_kg)
    return Scene("head-on", (a, b), Floor(friction=1.0, restitution=1.0))


def bouncing_ball(restitution: float, height_m: float = 0.5) -> Scene:
    """A 5 cm-radius ball dropped onto a floor of restitution 1 (so the pair's is the ball's)."""
    ball = Body("ball", Sphere(0.05), (0.0, 0.0, height_m), UPRIGHT, 0.5, restitution, mass_kg=0.2)
    return Scene("bouncing-ball", (ball,), Floor(friction=0.5, restitution=1.0))


def heavy_light_tower(heavy: str, ratio: float, rng: np.random.Generator) -> Scene:
    """A plank balanced on a post, a red stack on one end and a yellow stack on the other, about as
    far out: one colour ``ratio`` times denser, so the tower tips and falls toward it (Hamrick et
    al. 2016's "which is heavier?", watched instead of judged). Post and plank are grey, of known mass."""
    post = Box("post", (0.06, 0.1, 0.2), (0.0, 0.0, 0.1), UPRIGHT, 0.6, 0.0, density_kg_m3=500.0, group="grey")
    plank = Box("plank", (0.4, 0.1, 0.03), (float(rng.uniform(-0.005, 0.005)), 0.0, 0.215), UPRIGHT, 0.6, 0.0,
                density_kg_m3=500.0, group="grey")
    objects, reach = [post, plank], float(rng.uniform(0.11, 0.16))
    for side, colour in ((-1, "red"), (1, "yellow")):
        density = 500.0 * (ratio if colour == heavy else 1.0)
        x = side * (reach + float(rng.uniform(-0.01, 0.01)))
        for level in range(2):
            objects.append(Box(f"{colour}{level}", (0.07, 0.07, 0.07), (x, float(rng.uniform(-0.01, 0.01)),
                                                                         0.265 + 0.07 * level),
                               UPRIGHT, 0.6, 0.0, density_kg_m3=density, group=colour))
    return Scene("heavy-light-tower", tuple(objects), Floor(friction=0.6, restitution=0.0))


def probe_push(rng: np.random.Generator, mass_kg: float = 0.8, friction: float = 0.45, impulse_N_s: float = 1.2,
               position_sd_m: float = 0.002, at_s: float = 0.0) -> dict:
    """The worked example: the robot pushes a box of unknown mass and friction with a known impulse
    at ``at_s`` and watches it slide to a stop, for 1 s after the push."""
    change = (impulse_N_s / mass_kg, 0.0, 0.0)
    box = Box("box", (0.1, 0.1, 0.1), (0.0, 0.0, 0.05), UPRIGHT, friction, 0.0, mass_kg=mass_kg,
              linear_velocity_m_s=change if at_s == 0 else (0.0, 0.0, 0.0))
    scene = Scene("probe-push", (box,), Floor(friction=1.0, restitution=0.0),
                  pushes=(TimedPush("box", at_s, change),) if at_s > 0 else ())
    observation = observe(scene, at_s + 1.0, rng, position_sd_m=position_sd_m, unknowns=[
        {"object": "box", "property": "mass_kg", "prior": {"log_uniform": [0.05, 5.0]}},
        {"object": "box", "property": "friction", "prior": {"uniform": [0.05, 1.2]}}],
        actions=[{"kind": "push", "object": "box", "at_s": at_s, "impulse_N_s": [impulse_N_s, 0.0]}])
    # the scene the robot knows: the box at rest before its push
    observation["scene"]["objects"][0]["linear_velocity_m_s"] = [0.0, 0.0, 0.0]
    return observation


@dataclass(frozen=True)
class KnownCase:
    """An observation made at known values: ``truth`` by unknown label; ``heavier``: (a, b) mass
    labels where a's truth is the larger. ``scored``: what the observation can tell (a single
    mass is not, where only the ratio shows: then "ratio", m_a / m_b of ``heavier``)."""

    family: str
    observation: dict
    truth: dict
    heavier: tuple[str, str] | None = None
    scored: tuple[str, ...] = ()

    @property
    def true_ratio(self) -> float:
        return self.truth[self.heavier[0]] / self.truth[self.heavier[1]]


def slide_case(seed: int) -> KnownCase:
    """A box slid at a random heading and speed: its friction (stops after v^2 / (2 mu g))."""
    rng = np.random.default_rng(seed)
    friction, speed, heading = rng.uniform(0.2, 0.9), rng.uniform(1.0, 2.0), rng.uniform(-np.pi, np.pi)
    obs = observe(sliding_box(speed, friction, heading), 1.2, rng, unknowns=[
        {"object": "box", "property": "friction", "prior": {"uniform": [0.05, 1.2]}}])
    return KnownCase("slide", obs, {"box.friction": friction}, scored=("box.friction",))


def head_on_case(seed: int) -> KnownCase:
    """Two boxes colliding head-on: their mass ratio (momentum exchanged)."""
    rng = np.random.default_rng(seed)
    ma, mb = np.exp(rng.uniform(np.log(0.2), np.log(2.0), 2))
    obs = observe(head_on(ma, mb), 1.0, rng, unknowns=[
        {"object": "a", "property": "mass_kg", "prior": {"log_uniform": [0.05, 5.0]}},
        {"object": "b", "property": "mass_kg", "prior": {"log_uniform": [0.05, 5.0]}}])
    heavier = ("a.mass_kg", "b.mass_kg") if ma > mb else ("b.mass_kg", "a.mass_kg")
    return KnownCase("head-on", obs, {"a.mass_kg": ma, "b.mass_kg": mb}, heavier, ("ratio",))


def bounce_case(seed: int) -> KnownCase:
    """A ball dropped from 0.5 m: its restitution (each bounce e^2 as high)."""
    rng = np.random.default_rng(seed)
    restitution = rng.uniform(0.2, 0.8)
    obs = observe(bouncing_ball(restitution), 1.5, rng, unknowns=[
        {"object": "ball", "property": "restitution", "prior": {"uniform": [0.0, 1.0]}}])
    return KnownCase("bounce", obs, {"ball.restitution": restitution}, scored=("ball.restitution",))


def tower_case(seed: int) -> KnownCase:
    """A falling tower of red and yellow blocks on a balance, one colour 2-4x denser: which is heavier."""
    rng = np.random.default_rng(seed)
    heavy = "red" if rng.random() < 0.5 else "yellow"
    scene = heavy_light_tower(heavy, rng.uniform(2.0, 4.0), rng)
    prior = {"log_uniform": [0.05, 5.0]}
    obs = observe(scene, 1.5, rng, unknowns=[{"group": "red", "property": "mass_kg", "prior": prior},
                                             {"group": "yellow", "property": "mass_kg", "prior": prior}])
    masses = {g: next(b.resolved_mass_kg for b in scene.objects if b.group == g) for g in ("red", "yellow")}
    light = "yellow" if heavy == "red" else "red"
    return KnownCase("tower", obs, {f"group:{g}.mass_kg": m for g, m in masses.items()},
                     (f"group:{heavy}.mass_kg", f"group:{light}.mass_kg"), ("ratio",))


CASES = {"slide": slide_case, "head-on": head_on_case, "bounce": bounce_case, "tower": tower_case}
