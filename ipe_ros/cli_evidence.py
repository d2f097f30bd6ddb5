"""The command line's side of the evidence protocol (engine.evidence): every registered perception
source's options on ``ipe predict`` and ``ipe ask``, read into its evidence, and its recording
written. Nothing here knows a source by name."""

from __future__ import annotations

import argparse
import time
from typing import Any, Mapping

from .cli_inputs import add_rows
from .engine import ConfigError, ModelConfig
from .engine.evidence import resolve
from .engine.perceptions import PerceptionSource, perception_names, perception_source


def _needing() -> list[PerceptionSource]:
    return [s for s in map(perception_source, perception_names()) if s.needs is not None and s.needs.options]


def add_evidence_options(parser: argparse.ArgumentParser) -> None:
    """Each source's options, in a group of its own."""
    for source in _needing():
        group = parser.add_argument_group(f"{source.name} perception")
        add_rows(group, source.needs.options)


def _given(args, source: PerceptionSource) -> list[str]:
    return [o.flag for o in source.needs.options if getattr(args, o.field, None) is not None]


def _flags(source: PerceptionSource) -> str:
    flags = [o.flag for o in source.needs.options]
    return flags[0] if len(flags) == 1 else f"{', '.join(flags[:-1])} and {flags[-1]}"


def option_values(args, source: PerceptionSource) -> dict[str, Any]:
    return {o.field: getattr(args, o.field, None) for o in source.needs.options}


def _read(args, source: PerceptionSource, field: str) -> Any:
    values = option_values(args, source)
    lacking = [o for o in source.needs.required() if values[o.field] is None]
    if lacking:
        required = [f"{o.flag} {o.metavar}" for o in source.needs.required()]
        listed = required[0] if len(required) == 1 else f"{', '.join(required[:-1])} and {required[-1]}"
        raise ConfigError(field, f"{source.name} perception needs {listed}")
    return source.needs.read(values)


def evidence_for(args, perception: str) -> Any:
    """``ipe predict``: the evidence ``perception`` needs, read from its options (None: it needs
    none); another source's options given are refused."""
    for other in _needing():
        if other.name != perception and _given(args, other):
            raise ConfigError("--perception", f"{_flags(other)} need --perception {other.name}")
    source = perception_source(perception)
    if source.needs is None or not source.needs.options:
        return None
    return _read(args, source, "--perception")


def asked_source(args) -> PerceptionSource | None:
    """``ipe ask``: the source whose options were given (its evidence replaces --sigma), or None."""
    given = [s for s in _needing() if _given(args, s)]
    if len(given) > 1:
        raise ConfigError(_given(args, given[1])[0], f"one perception at a time: {given[0].name} "
                                                     f"({_given(args, given[0])[0]}) is given already")
    return given[0] if given else None


def perceive_for_question(args, scene, source: PerceptionSource):
    """``ipe ask`` with a source's options: its --samples scenes for the scene asked about (one
    chain, in this process, within its share of --budget; --budget then keeps what it left)."""
    field = source.needs.options[0].flag
    if args.ground_truth:
        raise ConfigError("--ground-truth", f"takes the scene exactly as given, but {field} draws it from the "
                                            f"{source.name} posterior; drop one of them")
    evidence = _read(args, source, field)  # read first: a missing option is said before anything runs
    model = ModelConfig(samples=args.samples, perception=source.name)
    share = None if args.budget_s is None else args.budget_s * source.needs.budget_share
    started = time.perf_counter()
    perceived = source.perceive(scene, model, args.seed, None, evidence, share)
    if args.budget_s is not None:
        args.budget_s = max(args.budget_s - (time.perf_counter() - started), 1e-3)
    return perceived, evidence


def record(args, source: PerceptionSource, scene, perceived, evidence: Any) -> str | None:
    """The source's recording of its chain, when its option asks for one (the file written)."""
    if source.needs is None or not source.needs.record:
        return None
    return resolve(source.needs.record)(option_values(args, source), scene, perceived, evidence)


def refuse_many(source: PerceptionSource, scenes: list, path: str, evidence: Any) -> None:
    """One piece of evidence describes one scene."""
    if evidence is not None and len(scenes) != 1:
        raise ConfigError(source.needs.options[0].flag, f"{source.needs.describes}, but {path} holds {len(scenes)}")


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
