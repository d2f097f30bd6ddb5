"""Where a prediction's k noisy scenes come from: perception sources, registered as the queries are.

A source either leaves the scene as given to the model's own noise (``gaussian``: sigma, the paper's
IPE) or draws the k scenes from a posterior (``vision``: the SI's images of the scene, rendered from
it; ``depth``: a robot's depth images). A source that needs evidence declares it
(``engine.evidence.Evidence``): the CLI's options and the node's topics that fill it. ``predict``
asks the source, never the name: a new source is one ``register_perception`` call, and the CLI's
``--perception`` and the node's ``perception`` parameter offer it, with its options and topics.

A source's chain returns ``Perceived`` scenes (the protocol below; vision's ``PerceivedScenes``,
depth's ``DepthPerceivedScenes``, a plugin's own type).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Protocol, runtime_checkable

from .errors import ConfigError, shown
from .evidence import Evidence
from .input_row import Input

#: run(scene, model, seed, map_fn, evidence, budget_s) -> perceived scenes: the chain, through
#: ``map_fn`` when given (the prediction's workers), within ``budget_s`` wall seconds when given
PerceiveFn = Callable[[Any, Any, int, Any, Any, "float | None"], Any]


@runtime_checkable
class Perceived(Protocol):
    """What a source's chain returns: ``scenes`` (at least k, sample i starts from scene i),
    ``refined`` (the scene at the posterior's mean, published on the node's ``~/perceived_scene``;
    None: none), ``with_samples(k)`` (k of them for a question's smaller k, no new chain) and
    ``to_dict()`` (what the answer reports under ``request.perception``, with a ``kind``)."""

    scenes: tuple
    refined: Any

    def with_samples(self, k: int) -> "Perceived": ...

    def to_dict(self) -> dict: ...


@dataclass(frozen=True)
class PerceptionSource:
    """One source of the k noisy scenes.

    posterior: the k scenes are drawn from a posterior (the model's sigma is unused, and a prediction
      with it is never deterministic); False: the model's own noise applies to the scene as given.
    run: draws the perceived scenes (a ``PerceiveFn``); None with ``posterior`` False.
    needs: the evidence it draws them given, and how the doors fill it (None: the scene alone).
    on_node: the node can feed it (a source needing evidence the node does not subscribe to cannot).
    describe: the text report's line from the answer's ``request.perception`` (None: no line).
    options: its command-line options (``Input`` rows with a flag, default None), offered by
      ``ipe predict`` (and, for a source that needs evidence, ``ipe ask``) and refused without
      ``--perception <name>``; those not in ``optional`` are required.
    configure: the option values -> the request's arguments they set (``build_request``: vision's
      chain settings); None: none.
    recording, record: the option naming a recording of the chain, and the ``"module:function"``
      that writes it (recordings import the viewer's library, which the engine does not), called
      with (option values, scene, perceived, evidence, model) -> the file written or None.
    heading: the text report's first line's perception part for a model (None: "<name> (sigma
      unused)").
    """

    name: str
    summary: str
    posterior: bool
    run: PerceiveFn | None = None
    needs: Evidence | None = None
    on_node: bool = True
    describe: Callable[[dict], str] | None = None
    options: tuple[Input, ...] = ()
    optional: frozenset[str] = frozenset()
    configure: Callable[[Mapping[str, Any]], dict] | None = None
    recording: str = ""
    record: str = ""
    heading: Callable[[Any], str] | None = None

    def required(self) -> tuple[Input, ...]:
        return tuple(o for o in self.options if o.field not in self.optional)

    def where(self) -> str:
        """Where the doors take its evidence from, for errors."""
        doors = []
        if self.required():
            doors.append("ipe predict's " + ", ".join(o.flag for o in self.required()))
        if self.needs is not None and self.needs.topics:
            doors.append("the node's " + ", ".join(t.name for t in self.needs.topics))
        return "; ".join(doors) or "no door fills it"

    def perceive(self, scene, model, seed: int, map_fn=None, evidence=None, budget_s: float | None = None):
        """The perceived scenes for ``scene``: its chain, within its share of ``budget_s`` (a
        prediction's whole budget; ``Evidence.budget_share``; a source that needs no evidence runs
        its length)."""
        if self.run is None:
            raise ConfigError("perception", f"{self.name} perception draws no scenes of its own")
        if self.needs is not None and evidence is None:
            raise ConfigError("perception", f"{self.name} perception needs {self.needs.what}: give them to predict as "
                                            f"its evidence ({self.where()})")
        share = None if budget_s is None or self.needs is None else budget_s * self.needs.budget_share
        perceived = self.run(scene, model, seed, map_fn, evidence, share)
        if not isinstance(perceived, Perceived):
            raise TypeError(f"perception {self.name}'s run returned a {type(perceived).__name__}, which is not "
                            "Perceived (engine.perceptions): give it scenes, refined, with_samples(k) and to_dict()")
        return perceived

    def perceive_within(self, scene, model, seed: int, map_fn, evidence, budget_s: float | None):
        """``perceive``, and what its chain left of ``budget_s`` for the samples (at least 1 ms; all
        of it for a source whose chain has no deadline)."""
        started = time.perf_counter()
        perceived = self.perceive(scene, model, seed, map_fn, evidence, budget_s)
        if budget_s is None or self.needs is None:
            return perceived, budget_s
        return perceived, max(budget_s - (time.perf_counter() - started), 1e-3)


_SOURCES: dict[str, PerceptionSource] = {}
BUILT_IN: set[str] = set()


def register_perception(source: PerceptionSource, built_in: bool = False) -> PerceptionSource:
    """Add a source (a name not taken yet); ``built_in``: the engine's own, never unregistered."""
    if not isinstance(source, PerceptionSource):
        raise TypeError(f"register_perception takes a PerceptionSource, got {type(source).__name__}")
    if source.name in _SOURCES:
        raise ValueError(f"a perception named {source.name!r} is registered already")
    if not source.name.isidentifier():
        raise ValueError(f"a perception's name must be an identifier, got {source.name!r}")
    _SOURCES[source.name] = source
    if built_in:
        BUILT_IN.add(source.name)
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


GAUSSIAN = register_perception(PerceptionSource(
    "gaussian", "horizontal Gaussian noise of SD sigma on every object (the paper's IPE)", posterior=False),
    built_in=True)
# vision and depth are registered by their room (vision/sources.py), which the engine's package imports
