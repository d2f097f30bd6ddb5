"""The engine's own perception sources besides gaussian, registered in this order when the engine's
package is imported: ``vision`` (the SI's Bayesian vision system on images rendered from the scene)
and ``depth`` (the posterior given a robot's depth images; its evidence in ``depth_source``)."""

from __future__ import annotations

from typing import Any, Mapping

from ..errors import ConfigError
from ..input_row import Input
from ..perceptions import PerceptionSource, register_perception
from .depth_source import DEPTH_EVIDENCE, DEPTH_OPTIONS, describe_depth, run_depth

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


#: the command line's vision options: the chain's length and resolution, and a recording of it
VISION_OPTIONS = (
    Input("chain_samples", "int", None, "samples", "vision: Metropolis-Hastings samples (a fifth is burn-in)",
          flag="--chain-samples", in_request=False, unset_means="5000, the SI's", metavar="N"),
    Input("vision_resolution", "int", None, "pixels", "vision: rendered image size (blur and SD scale with it)",
          flag="--vision-resolution", in_request=False, unset_means="256, the SI's", metavar="PX"),
    Input("vision_rrd", "name", None, "path", "vision: write the observed images, the posterior sample cloud and the "
          "acceptance trace to a rerun recording", flag="--vision-rrd", in_request=False, unset_means="none",
          metavar="FILE"))
_VISION_FLAGS = {"vision.chain_samples": "--chain-samples", "vision.burn_in": "--chain-samples",
                 "vision.resolution_px": "--vision-resolution"}


def _vision_settings(values: Mapping[str, Any]) -> dict:
    """The request's ``vision`` (the chain's settings) from the options; errors named as the options."""
    from .likelihood import VisionSettings

    changes = {}
    if values.get("chain_samples") is not None:
        changes.update(chain_samples=values["chain_samples"], burn_in=values["chain_samples"] // 5)
    if values.get("vision_resolution") is not None:
        changes.update(resolution_px=values["vision_resolution"])
    try:
        return {"vision": VisionSettings(**changes)}
    except ConfigError as exc:
        raise ConfigError(_VISION_FLAGS.get(exc.field, exc.field), exc.problem) from None


def _vision_heading(model) -> str:
    return f"vision ({model.vision.chain_samples} MH samples, {model.vision.resolution_px} px)"


VISION = register_perception(PerceptionSource(
    "vision", "the SI's Bayesian vision system: samples of the posterior given images of the scene",
    posterior=True, run=perceive_vision, on_node=False, describe=_describe_vision, options=VISION_OPTIONS,
    optional=frozenset(o.field for o in VISION_OPTIONS), configure=_vision_settings, recording="vision_rrd",
    record="ipe_ros.viz.perception_log:record_vision", heading=_vision_heading), built_in=True)
DEPTH = register_perception(PerceptionSource(
    "depth", "samples of the posterior given the robot's depth images", posterior=True, run=run_depth,
    needs=DEPTH_EVIDENCE, describe=describe_depth, options=DEPTH_OPTIONS, optional=frozenset({"depth_rrd"}),
    recording="depth_rrd", record="ipe_ros.viz.perception_log:record_depth"), built_in=True)
