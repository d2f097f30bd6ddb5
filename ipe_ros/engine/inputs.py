"""One table of a prediction's inputs: how the engine names each one, how the command line and
the node's parameters spell it, its unit and what it means.

The engine's errors name the engine's field (``ConfigError("sigma_m", ...)``); a person who typed
``--sigma 99`` or set the parameter ``sigma`` must read the name they used. ``spelled`` and
``as_spelled`` translate through this table, so the CLI and the node name every input the same way
their users do, and a new input is one row here (tests/test_inputs.py checks the table against the
CLI's options and the node's parameters).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .errors import ConfigError
from .query.parameters import query_parameters

Caller = Literal["cli", "ros"]


@dataclass(frozen=True)
class Input:
    """One input. ``flag``: the CLI's option of ``ipe predict`` (None: none); ``parameter``: the
    node's ROS parameter (None: none); ``unit``: of the value as the user gives it."""

    field: str
    flag: str | None
    parameter: str | None
    unit: str
    meaning: str


INPUTS: tuple[Input, ...] = (
    Input("samples", "--samples", "samples", "count", "Monte Carlo samples k"),
    Input("sigma_m", "--sigma", "sigma", "m", "position noise SD"),
    Input("phi_m_s2", "--phi", "phi", "m/s^2", "latent push: the support's horizontal acceleration for 0.2 s"),
    Input("force_direction_rad", "--force-direction", "force_direction_deg", "deg", "cued push direction"),
    Input("mu", "--mu", "mu", "ratio", "heavy/light density ratio"),
    Input("preset", "--preset", "preset", "name", "simulation settings"),
    Input("horizon_s", "--horizon", "horizon_s", "s", "simulated seconds per rollout"),
    Input("seed", "--seed", "seed", "integer", "random seed"),
    Input("queries", "--query", "queries", "names", "what to answer (engine/query)"),
    Input("contact", "--contact", "contact_pairs", "A:B pairs", "the contact query's pairs"),
    Input("ci_width", "--ci-width", "target_ci_width", "probability", "anytime sampling: target interval width"),
    Input("self_check", "--no-self-check", "self_check", "flag", "check the fast physics against the reference"),
    Input("deadline_s", "--deadline", "deadline_s", "s", "anytime sampling: stop drawing samples by then"),
    Input("budget_s", "--budget", "budget_s", "s", "the most wall seconds one prediction may take"),
    Input("self_check.verify_samples", "--verify-samples", "verify_samples", "count", "samples rerun at the reference"),
    Input("perception", "--perception", "perception", "name", "where the noisy scenes come from"),
    Input("ground_truth", "--ground-truth", "ground_truth", "flag", "the scene exactly as given: no noise, one rollout"),
    Input("max_objects", None, "max_objects", "count", "scenes with more objects are refused"),
    Input("workers", "--workers", "workers", "count", "worker processes"),
    Input("fell_off", "--fell-off", None, "flag", "robot questions: also which objects end off the table"),
)

_BY_FIELD = {i.field: i for i in INPUTS}


def spelled(field: str, by: Caller) -> str:
    """``field`` as the CLI (``by="cli"``) or the node's parameters (``"ros"``) spell it; other
    fields (a scene's paths, a setting with no spelling of its own) unchanged."""
    row = _BY_FIELD.get(field)
    name = None if row is None else (row.flag if by == "cli" else row.parameter)
    if row is None and by == "cli":  # a query's own parameter (query.parameters): --<query>-<field>
        name = next((p.flag for p in query_parameters() if p.name == field), None)
    return field if name is None else name


def as_spelled(exc: ConfigError, by: Caller) -> ConfigError:
    """The same error naming its input as the caller's user spelled it."""
    name = spelled(exc.field, by)
    return exc if name == exc.field else ConfigError(name, exc.problem)
