"""A parameter set: model inputs saved to a file (by ``ipe fit``) and loaded by ``ipe predict
--inputs-from``, ``ipe ask --inputs-from`` and the node's ``inputs_from`` parameter.

    {"format": "ipe_ros.inputs/1", "inputs": {"sigma": 0.02, "launch_direction_sd_deg": 10.0},
     "provenance": {...}, ...}

``inputs`` names the model's inputs as the node's parameters spell them (``MODEL_INPUTS``); a loaded
value replaces the default, and an input given explicitly (a flag, a parameter override) wins over
the file. Everything else in the file (the provenance, a fit's response mapping) is kept for people
and ignored here.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Mapping

from .errors import ConfigError, shown
from .safe_files import UnreadableFile, read_file_bounded
from .inputs import INPUTS, Input, from_node

FORMAT = "ipe_ros.inputs/1"
#: the inputs a parameter set may hold: the model's (not the simulation's, stopping or budget)
MODEL_INPUTS = ("sigma", "phi", "mu", "mass_log_sd", "friction_log_sd", "restitution_spread", "launch_speed_log_sd",
                "launch_direction_sd_deg")
MAX_BYTES = 1 << 20
_ROWS = {r.parameter: r for r in INPUTS if r.parameter in MODEL_INPUTS}


def model_input(name: str) -> Input:
    """The row of a model input named as the node's parameter; a ConfigError naming it otherwise."""
    found = _ROWS.get(name)
    if found is None:
        raise ConfigError(name, f"is not a model input; one of {', '.join(MODEL_INPUTS)}")
    return found


def checked_value(name: str, value: Any) -> Any:
    """``value`` of input ``name`` as the request takes it (a tuple for phi), within its row's range."""
    found = model_input(name)
    numbers = list(value) if found.kind == "floats" and isinstance(value, (list, tuple)) else [value]
    for number in numbers:
        if isinstance(number, bool) or not isinstance(number, (int, float)) or not math.isfinite(number):
            raise ConfigError(name, f"must be a finite number, got {shown(value)}")
        if found.range is not None and not found.range[0] <= number <= found.range[1]:
            raise ConfigError(name, f"must be in [{found.range[0]:g}, {found.range[1]:g}] {found.unit}, got {number:g}")
    if found.kind == "floats":
        return tuple(float(n) for n in numbers)
    return float(value)


def load_input_set(path: str | Path) -> dict[str, Any]:
    """The request's arguments (``build_request``'s keywords, by input field) a parameter set holds."""
    path = Path(path)
    try:  # never waiting on a FIFO, nor reading a device or a huge file whole
        content = read_file_bounded(path, MAX_BYTES, "a parameter set")
    except UnreadableFile as exc:
        raise ConfigError("inputs_from", str(exc)) from None
    try:
        data = json.loads(content.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError("inputs_from", f"{path.name} is not JSON ({exc})") from None
    if not isinstance(data, dict):
        raise ConfigError("inputs_from", f"{path.name} holds a JSON {type(data).__name__}, not a parameter set "
                                         f"(an object of format {FORMAT!r}, made by ipe fit)")
    if data.get("format") != FORMAT:
        raise ConfigError("inputs_from", f"{path.name}: format must be {FORMAT!r} (made by ipe fit), got "
                                         f"{shown(data.get('format'))}")
    inputs = data.get("inputs")
    if not isinstance(inputs, dict):
        raise ConfigError("inputs_from", f"{path.name}: 'inputs' must be an object of model inputs")
    try:
        return request_arguments_of(inputs)
    except ConfigError as exc:
        raise ConfigError("inputs_from", f"{path.name}: {exc}") from None


def request_arguments_of(values: Mapping[str, Any]) -> dict[str, Any]:
    """``build_request``'s keywords of model inputs named as the node's parameters, each checked
    against its row's range (a ConfigError naming it); a value that means "not set" (mu 0: the
    scene's own masses) left out, as the node reads its parameters (``inputs.from_node``)."""
    out: dict[str, Any] = {}
    for name, value in values.items():
        found = model_input(name)
        given = from_node(found, checked_value(name, value))
        if given is not None:
            out[found.field] = given
    return out
