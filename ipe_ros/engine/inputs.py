"""One table of a prediction's inputs, from which the command line's options and the node's
parameter descriptors are made.

A row says what an input is once: the request's argument it sets (``engine.request.build_request``),
its kind, default, range, choices, unit and help, and how each door spells it (the CLI's option of
``ipe predict`` and ``ipe ask``, the node's ROS parameter). ``cli_inputs.add_input_options`` makes the
options and ``ros.params`` the descriptors from these rows, and both turn what their user gave back
into the request's arguments through them, so a new input is one row here.

The doors differ only where their media do, and the row says how:
- a node parameter cannot be None: ``unset`` is the value that means "not set" (0 for an off
  stopping rule or the preset's horizon, NaN for any push direction);
- a CLI flag is a switch: a ``bool`` input is ``--x``/``--no-x``;
- contact pairs are a repeated ``--contact A:B`` and one ``contact_pairs`` string ("A:B,C:D").

The engine's errors name the engine's field (``ConfigError("sigma_m", ...)``); ``spelled`` and
``as_spelled`` rename them through this table (``errors_as`` lists an input's other engine names), so
a person who typed ``--sigma 99`` or set ``sigma`` reads the name they used.
"""

from __future__ import annotations

import array
import math
from typing import Any, Mapping

from .config import (MAX_SAMPLES, DEFAULT_BUDGET_S, DEFAULT_PRESET, DEFAULT_QUERIES, DEFAULT_SAMPLES, DEFAULT_SIGMA_M, PRESETS,
                     default_workers)
from .errors import ConfigError
from .checking.fidelity import DEFAULT_CHECK
from .perceptions import perception_names
from .query import QUERIES
from .query.contact import parse_pairs
from .query.parameters import query_parameters
from .scene import limits
from .scene.bodies import DEFAULT_MAX_OBJECTS

from .input_row import Caller, Input, Kind  # noqa: F401 - the row, re-exported


def _presets() -> tuple[str, ...]:
    return tuple(sorted(PRESETS))


def _queries() -> tuple[str, ...]:
    return tuple(QUERIES)


INPUTS: tuple[Input, ...] = (
    Input("samples", "int", DEFAULT_SAMPLES, "count", "Monte Carlo samples k (the paper: 48)",
          "--samples", "samples", range=(1, MAX_SAMPLES), metavar="K"),
    Input("sigma_m", "float", DEFAULT_SIGMA_M, "m",
          "position noise SD, metres (the paper: 0.2 block short sides = 0.04 m for 0.2 m blocks; 0 drops the "
          "model's own noise, not the noise a scene gives its bodies: the ground truth drops both)",
          "--sigma", "sigma", range=(0.0, limits.MAX_SIGMA_M), metavar="M"),
    Input("phi_m_s2", "floats", (0.0,), "m/s^2",
          "latent push: the support's horizontal acceleration for 0.2 s, m/s^2; several values are averaged "
          "(0: no push)", "--phi", "phi", range=(0.0, limits.MAX_PHI_M_S2), metavar="A[,A...]"),
    Input("force_direction_deg", "float", None, "degrees",
          "cued push direction in degrees in the scene frame (0 = +x, counter-clockwise), pushes drawn within "
          "+-45 deg of it", "--force-direction", "force_direction_deg", unset=math.nan, unset_means="any direction",
          errors_as=("force_direction_rad",), metavar="DEG", constraints="finite degrees, or NaN for any direction"),
    Input("mu", "float", None, "ratio", "heavy/light density ratio for bodies in group 'heavy'", "--mu", "mu",
          range=(0.0, limits.MAX_MASS_RATIO), unset=0.0, unset_means="the scene's own masses", metavar="R"),
    Input("mass_log_sd", "float", 0.0, "log SD", "uncertain masses: every dynamic object without a mass_prior of its "
          "own draws its mass per sample, log-normal around the scene's (0: exact, as given)", "--mass-log-sd",
          "mass_log_sd", range=(0.0, 5.0), metavar="S"),
    Input("friction_log_sd", "float", 0.0, "log SD", "uncertain frictions: every surface (objects and support) "
          "without a friction_prior of its own draws its friction per sample, log-normal around the scene's (0: "
          "exact)", "--friction-log-sd", "friction_log_sd", range=(0.0, 5.0), metavar="S"),
    Input("restitution_half_width", "float", 0.0, "restitution", "uncertain restitutions: every surface without a "
          "restitution_prior of its own draws its restitution per sample, uniform within +- this of the scene's, "
          "cut to [0, 1] (0: exact)", "--restitution-spread", "restitution_spread", range=(0.0, 1.0), metavar="W"),
    Input("launch_speed_log_sd", "float", 0.0, "log SD", "uncertain launches: every object moving at t = 0 has its "
          "initial speed (linear and angular) scaled per sample by a log-normal factor of this log SD (0: exact)",
          "--launch-speed-log-sd", "launch_speed_log_sd", range=(0.0, 1.5), metavar="S",
          errors_as=("speed_log_sd",)),
    Input("launch_direction_sd_deg", "float", 0.0, "degrees", "uncertain launches: every object moving at t = 0 has "
          "its initial velocity turned about the vertical per sample by a normal angle of this SD, degrees (0: "
          "exact)", "--launch-direction-sd", "launch_direction_sd_deg", range=(0.0, 180.0), metavar="DEG",
          errors_as=("direction_sd_rad",)),
    Input("ground_truth", "bool", False, "flag",
          "the ground-truth model: the scene exactly as given, one deterministic rollout (sigma and phi read as 0, "
          "and no body's own position or yaw noise)", "--ground-truth", "ground_truth"),
    Input("perception", "name", "gaussian", "name",
          "where the k noisy scenes come from: gaussian (sigma), vision (a posterior given rendered images), depth "
          "(the posterior given a depth image, its camera_info and the camera's pose; sigma unused), or another "
          "registered perception (engine.perceptions)", "--perception", "perception", choices=perception_names),
    Input("queries", "names", tuple(q for q in QUERIES if q in DEFAULT_QUERIES), "names",
          "what to answer (bump needs a table, contact its pairs; docs/model.md)", "--query", "queries",
          choices=_queries, metavar="NAMES"),
    Input("contact", "pairs", (), "A:B pairs",
          "the contact query: will A touch B within the horizon? (B may be 'support'; names holding ':' as JSON: "
          "'[[\"cup:1\", \"glass\"]]'); adds contact to the queries", "--contact", "contact_pairs", metavar="A:B",
          constraints="empty, or comma-separated A:B object name pairs, or a JSON list of pairs"),
    Input("preset_name", "name", DEFAULT_PRESET, "name", "simulation settings: " + ", ".join(
          f"{name} ({s.time_step_s * 1000:g} ms steps, {s.horizon_s:g} s, {s.solver.iterations} solver iterations)"
          for name, s in PRESETS.items()), "--preset", "preset", choices=_presets, errors_as=("preset",)),
    Input("horizon_s", "float", None, "s", "simulated seconds per rollout for scenes that give no horizon_s of their "
          "own", "--horizon", "horizon_s", range=(0.0, 60.0), unset=0.0, unset_means="the preset's", metavar="S"),
    Input("until_rest", "bool", False, "flag", "end each rollout once everything is at rest (early termination, also "
          "for presets without it); with a horizon: until at rest, at most that long", "--until-rest", "until_rest"),
    Input("seed", "int", 0, "integer", "random seed: a prediction is a function of (scene, inputs, seed)",
          "--seed", "seed", range=(0, 2**31 - 1), metavar="N"),
    Input("ci_width", "float", None, "probability", "anytime sampling: stop once the 95% interval of the fall "
          "fraction is at most this wide (needs the fall or any_fall query)",
          "--ci-width", "target_ci_width", range=(0.0, 1.0), unset=0.0, unset_means="off", metavar="W"),
    Input("deadline_s", "float", None, "s", "anytime sampling: stop drawing samples before this many seconds",
          "--deadline", "deadline_s", range=(0.0, 3600.0), unset=0.0, unset_means="off (all k samples)", metavar="S"),
    Input("budget_s", "float", DEFAULT_BUDGET_S, "s", "compute budget: the most wall seconds one prediction may take; "
          "samples still running then are cut off (stopped_by: budget) and scenes whose one rollout cannot fit are "
          "refused", "--budget", "budget_s", range=(0.1, 3600.0), metavar="S"),
    Input("self_check", "bool", True, "flag", "check the fast physics against the converged reference on the same "
          "noisy scenes (refine unhealthy rollouts, verify samples, rerun everything on disagreement; the answer's "
          "fidelity says what happened; docs/model.md, 'Self-checking answers'); off: the fast physics alone, "
          "answers 'unverified'", "--self-check", "self_check"),
    Input("verify_samples", "int", DEFAULT_CHECK.verify_samples, "count",
          "samples rerun at the reference settings to verify the answer", "--verify-samples", "verify_samples",
          range=(0, 100), errors_as=("self_check.verify_samples",), requires="self_check", metavar="N"),
    Input("always_verify", "bool", DEFAULT_CHECK.always_verify, "flag", "verify also answers inside the envelope the "
          "fast physics was validated over (boxes at rest on a floor, no push: docs/model.md, 'Self-checking "
          "answers'), which otherwise answer 'validated' without reference reruns", "--always-verify",
          "always_verify", errors_as=("self_check.always_verify",)),
    Input("workers", "int", default_workers(), "count", "simulation worker processes (0: in this process; default "
          "one per CPU, at most 8)", "--workers", "workers", range=(0, 64), in_request=False, fixed_at_start=True, metavar="W"),
    Input("max_objects", "int", DEFAULT_MAX_OBJECTS, "count", "scenes with more objects are refused",
          None, "max_objects", range=(1, 10000), in_request=False),
    Input("fell_off", "bool", False, "flag", "robot questions: also which objects end off the table",
          "--fell-off", None, in_request=False),
)

_BY_FIELD = {name: row for row in INPUTS for name in (row.field, *row.errors_as)}


def row(field: str) -> Input:
    """The row of ``field`` (or of one of its ``errors_as`` names)."""
    return _BY_FIELD[field]


def spelled(field: str, by: Caller) -> str:
    """``field`` as the CLI (``by="cli"``) or the node's parameters (``"ros"``) spell it; other
    fields (a scene's paths, a setting with no spelling of its own) unchanged."""
    found = _BY_FIELD.get(field)
    name = None if found is None else (found.flag if by == "cli" else found.parameter)
    if found is None and by == "cli":  # a query's own parameter (query.parameters): --<query>-<field>
        name = next((p.flag for p in query_parameters() if p.name == field), None)
    return field if name is None else name


def as_spelled(exc: ConfigError, by: Caller) -> ConfigError:
    """The same error naming its input as the caller's user spelled it."""
    name = spelled(exc.field, by)
    return exc if name == exc.field else ConfigError(name, exc.problem)


def node_default(found: Input) -> Any:
    """The node parameter's declared value: the default, or ``unset`` for an input not set."""
    if found.default is None:
        return found.unset
    if found.kind == "pairs":
        return ",".join(f"{a}:{b}" for a, b in found.default)
    return list(found.default) if found.kind in ("floats", "names") else found.default


def _is_unset(found: Input, value: Any) -> bool:
    if found.default is not None:
        return False
    if isinstance(found.unset, float) and math.isnan(found.unset):
        return isinstance(value, float) and math.isnan(value)
    return value == found.unset


def from_node(found: Input, value: Any) -> Any:
    """A node parameter's value as the request's argument (None where it says "not set")."""
    if _is_unset(found, value):
        return None
    if found.kind == "pairs":
        return parse_pairs(str(value), found.parameter)
    if found.kind == "floats":  # one number, as the node took before it took several, or a list
        numbers = [value] if isinstance(value, (int, float)) and not isinstance(value, bool) else \
            list(value) if isinstance(value, (list, tuple, array.array)) else None  # rclpy: array('d')
        if not numbers or \
                not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in numbers):
            raise ConfigError(found.parameter, f"must be a number or a non-empty list of numbers, got {value!r}")
        return tuple(float(v) for v in numbers)
    if found.kind == "names":
        return tuple(value)
    if found.kind == "float" and isinstance(found.unset, float) and math.isnan(found.unset) and math.isinf(value):
        raise ConfigError(found.parameter, f"must be finite {found.unit} or NaN ({found.unset_means}), got {value}")
    return {"int": int, "float": float, "bool": bool}.get(found.kind, str)(value)


def request_arguments(given: Mapping[str, Any]) -> dict[str, Any]:
    """The request's arguments (``build_request``'s keywords) of the inputs in ``given`` (by field)."""
    return {r.field: given[r.field] for r in INPUTS if r.in_request and r.field in given}
