"""The command line's side of the perception protocol (engine.perceptions, engine.evidence): every
registered source's options on ``ipe predict`` (and, for a source that needs evidence, ``ipe ask``),
read into its evidence and its request arguments, and its recording written. Nothing here knows a
source by name."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from typing import Any, Mapping

from .cli_inputs import add_rows
from .engine import ConfigError, ModelConfig
from .engine.evidence import resolve
from .engine.perceptions import PerceptionSource, perception_names, perception_source


def _with_options(evidence_only: bool = False) -> list[PerceptionSource]:
    sources = [s for s in map(perception_source, perception_names()) if s.options]
    return [s for s in sources if s.needs is not None] if evidence_only else sources


def add_perception_options(parser: argparse.ArgumentParser, evidence_only: bool = False) -> None:
    """Each source's options, in a group of its own (``evidence_only``: of sources that need evidence,
    for ``ipe ask``)."""
    for source in _with_options(evidence_only):
        add_rows(parser.add_argument_group(f"{source.name} perception"), source.options)


def _given(args, source: PerceptionSource) -> list[str]:
    return [o.flag for o in source.options if getattr(args, o.field, None) is not None]


def _listed(flags: list[str]) -> str:
    return flags[0] if len(flags) == 1 else f"{', '.join(flags[:-1])} and {flags[-1]}"


def option_values(args, source: PerceptionSource) -> dict[str, Any]:
    return {o.field: getattr(args, o.field, None) for o in source.options}


@dataclass(frozen=True)
class Chosen:
    """The perception asked for on the command line: its source, its option values, the evidence read
    from them (None: it needs none) and the request arguments they set."""

    source: PerceptionSource
    values: Mapping[str, Any]
    evidence: Any = None
    request_arguments: Mapping[str, Any] = field(default_factory=dict)

    def record(self, scene, perceived, model) -> str | None:
        """The source's recording of its chain, when its option asks for one (the file written)."""
        if not self.source.record or self.values.get(self.source.recording) is None:
            return None
        return resolve(self.source.record)(self.values, scene, perceived, self.evidence, model)

    def refuse_many(self, scenes: list, path: str) -> None:
        """Evidence describes one scene, and a recording records one."""
        if self.evidence is not None and len(scenes) != 1:
            raise ConfigError(self.source.required()[0].flag, f"{self.source.needs.describes}, but {path} holds "
                                                              f"{len(scenes)}")
        if self.values.get(self.source.recording) is not None and len(scenes) != 1:
            flag = next(o.flag for o in self.source.options if o.field == self.source.recording)
            raise ConfigError(flag, f"records one scene, but {path} holds {len(scenes)}; choose one with --tower")

    def heading(self, model) -> str:
        """The text report's perception part ("" for the model's own noise)."""
        if not self.source.posterior:
            return ""
        shown = self.source.heading(model) if self.source.heading is not None else f"{self.source.name} (sigma unused)"
        return f", perception = {shown}"


def _read(source: PerceptionSource, values: Mapping[str, Any], field_name: str) -> Any:
    """The evidence from the source's option values, or a ConfigError naming ``field_name`` when a
    required option is missing."""
    lacking = [o for o in source.required() if values[o.field] is None]
    if lacking:
        listed = _listed([f"{o.flag} {o.metavar}" for o in source.required()])
        raise ConfigError(field_name, f"{source.name} perception needs {listed}")
    return source.needs.read(values) if source.needs is not None and source.needs.read is not None else None


def chosen_perception(args, perception: str) -> Chosen:
    """``ipe predict``: what ``perception``'s options give; another source's options given are refused."""
    for other in _with_options():
        if other.name != perception and _given(args, other):
            raise ConfigError("--perception", f"{_listed([o.flag for o in other.options])} need --perception "
                                              f"{other.name}")
    source = perception_source(perception)
    if not source.options:
        return Chosen(source, {})
    values = option_values(args, source)
    evidence = _read(source, values, "--perception")
    return Chosen(source, values, evidence, source.configure(values) if source.configure is not None else {})


def asked_source(args) -> PerceptionSource | None:
    """``ipe ask``: the source whose options were given (its evidence replaces --sigma), or None."""
    given = [s for s in _with_options(evidence_only=True) if _given(args, s)]
    if len(given) > 1:
        raise ConfigError(_given(args, given[1])[0], f"one perception at a time: {given[0].name} "
                                                     f"({_given(args, given[0])[0]}) is given already")
    return given[0] if given else None


def perceive_for_question(args, scene, source: PerceptionSource) -> tuple[Any, Chosen]:
    """``ipe ask`` with a source's options: its --samples scenes for the scene asked about (one
    chain, in this process, within its share of --budget; --budget then keeps what it left)."""
    flag = source.required()[0].flag
    if args.ground_truth:
        raise ConfigError("--ground-truth", f"takes the scene exactly as given, but {flag} draws it from the "
                                            f"{source.name} posterior; drop one of them")
    values = option_values(args, source)
    evidence = _read(source, values, flag)  # read first: a missing option is said before anything runs
    model = ModelConfig(samples=args.samples, perception=source.name)
    perceived, args.budget_s = source.perceive_within(scene, model, args.seed, None, evidence, args.budget_s)
    return perceived, Chosen(source, values, evidence)


def describe_perceived(source: PerceptionSource, perceived) -> str:
    """The source's line for perceived scenes (their ``to_dict``), or how many there are."""
    if source.describe is None:
        return f"{len(perceived.scenes)} perceived scenes"
    return source.describe(perceived.to_dict())


def describe(predictions, perception: str) -> list[str]:
    """The perception's line per answer for the text report (none for a source without one)."""
    source = perception_source(perception)
    if source.describe is None:
        return []
    return [f"{p.scene}: {source.describe(p.request['perception'])}" for p in predictions
            if isinstance(p.request.get("perception"), Mapping)]
