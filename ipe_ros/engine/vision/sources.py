"""The engine's own perception sources besides gaussian, registered in this order when the engine's
package is imported: ``vision`` (the SI's Bayesian vision system on images rendered from the scene)
and ``depth`` (the posterior given a robot's depth images; its evidence in ``depth_source``)."""

from __future__ import annotations

from ..perceptions import PerceptionSource, register_perception
from .depth_source import DEPTH_EVIDENCE, describe_depth, run_depth

#: The vision chain's random stream, apart from the samples' (SeedSequence(seed).spawn(k)).
VISION_STREAM = 0x5EE


def perceive_vision(scene, model, seed: int, map_fn=None, evidence=None, budget_s: float | None = None):
    """The vision chain ``predict`` runs for this scene, model and seed (``vision.PerceivedScenes``);
    its images are rendered from the scene (the SI's stimuli), so it needs no evidence; it has no
    deadline (the SI's chain runs its length)."""
    from .perception import PerceptionTask, perceive_task

    task = PerceptionTask(scene=scene, k=model.samples, settings=model.vision, seed=(seed, VISION_STREAM))
    return map_fn(perceive_task, [task])[0] if map_fn is not None else perceive_task(task)


def _describe_vision(v: dict) -> str:
    return (f"vision chain acceptance {v['acceptance_rate']:.2f}, effective sample size "
            f"{v['effective_sample_size']:.0f} ({v['chain_samples']} samples, {v['burn_in']} burn-in)")


VISION = register_perception(PerceptionSource(
    "vision", "the SI's Bayesian vision system: samples of the posterior given images of the scene",
    posterior=True, run=perceive_vision, on_node=False, describe=_describe_vision), built_in=True)
DEPTH = register_perception(PerceptionSource(
    "depth", "samples of the posterior given the robot's depth images", posterior=True, run=run_depth,
    needs=DEPTH_EVIDENCE, describe=describe_depth), built_in=True)
