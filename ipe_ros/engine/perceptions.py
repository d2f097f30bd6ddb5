"""Where a prediction's k noisy scenes come from: perception sources, registered as the queries are.

A source either leaves the scene as given to the model's own noise (``gaussian``: sigma, the paper's
IPE) or draws the k scenes from a posterior given evidence (``vision``: the SI's images of the scene;
``depth``: a robot's depth images, which the caller brings as ``perceived``). ``predict`` asks the
source, never the name: a new source is one ``register_perception`` call, and the CLI's
``--perception`` and the node's ``perception`` parameter offer it.

A source's perceived scenes are any object with ``scenes`` (at least k) and ``to_dict()`` (what the
answer reports under ``request.perception``, with a ``kind``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from .errors import ConfigError, shown

#: run(scene, model, seed, map_fn) -> perceived scenes
PerceiveFn = Callable[[Any, Any, int, Any], Any]


@dataclass(frozen=True)
class PerceptionSource:
    """One source of the k noisy scenes.

    posterior: the k scenes are drawn from a posterior (the model's sigma is unused, and a prediction
      with it is never deterministic); False: the model's own noise applies to the scene as given.
    run: draws the perceived scenes for ``predict`` when the caller passes none (in a worker when a
      map is given); None: the caller must bring them, and ``evidence`` says what they are.
    on_node: the node can feed it (a source needing evidence the node does not subscribe to cannot).
    """

    name: str
    summary: str
    posterior: bool
    run: PerceiveFn | None = None
    evidence: str = ""
    on_node: bool = True

    def perceive(self, scene, model, seed: int, map_fn=None):
        if self.run is None:
            raise ConfigError("perception", f"{self.name} perception needs {self.evidence}: pass its perceived scenes "
                                            "to predict as perceived")
        return self.run(scene, model, seed, map_fn)


_SOURCES: dict[str, PerceptionSource] = {}


def register_perception(source: PerceptionSource) -> PerceptionSource:
    """Add a source (a name not taken yet)."""
    if not isinstance(source, PerceptionSource):
        raise TypeError(f"register_perception takes a PerceptionSource, got {type(source).__name__}")
    if source.name in _SOURCES:
        raise ValueError(f"a perception named {source.name!r} is registered already")
    if not source.name.isidentifier():
        raise ValueError(f"a perception's name must be an identifier, got {source.name!r}")
    _SOURCES[source.name] = source
    return source


def unregister_perception(name: str) -> None:
    """Remove a source registered at run time (a plugin unloaded, a test's own); built-ins stay."""
    if name in BUILT_IN:
        raise ValueError(f"{name!r} is built in")
    _SOURCES.pop(name, None)


def perception_names() -> tuple[str, ...]:
    return tuple(_SOURCES)


def perception_source(name) -> PerceptionSource:
    """The source named ``name``, or a ConfigError naming ``perception`` and the choices."""
    if not isinstance(name, str) or name not in _SOURCES:
        raise ConfigError("perception", f"must be one of {', '.join(_SOURCES)}, got {shown(name)}")
    return _SOURCES[name]


#: The vision chain's random stream, apart from the samples' (SeedSequence(seed).spawn(k)).
VISION_STREAM = 0x5EE


def perceive_vision(scene, model, seed: int, map_fn=None):
    """The vision chain ``predict`` runs for this scene, model and seed (``vision.PerceivedScenes``)."""
    from .vision.perception import PerceptionTask, perceive_task

    task = PerceptionTask(scene=scene, k=model.samples, settings=model.vision, seed=(seed, VISION_STREAM))
    return map_fn(perceive_task, [task])[0] if map_fn is not None else perceive_task(task)


GAUSSIAN = register_perception(PerceptionSource(
    "gaussian", "horizontal Gaussian noise of SD sigma on every object (the paper's IPE)", posterior=False))
VISION = register_perception(PerceptionSource(
    "vision", "the SI's Bayesian vision system: samples of the posterior given images of the scene",
    posterior=True, run=perceive_vision, on_node=False))
DEPTH = register_perception(PerceptionSource(
    "depth", "samples of the posterior given the robot's depth images", posterior=True,
    evidence="the depth images (vision.depth.perceive_depth; the CLI's --depth, the node's depth topics)"))

BUILT_IN = frozenset(_SOURCES)
