"""One prediction request, built and validated once from the inputs every caller has.

The CLI's options and the node's parameters are two spellings of the same inputs (engine.inputs);
``build_request`` turns them into the engine's values (model, settings, queries, stopping, budget,
self-check) with one set of checks, so both refuse the same things with the same words. Errors
name the engine's fields; ``inputs.as_spelled`` renames them for the caller's user.
"""

from __future__ import annotations

import math
from typing import Any, Iterable, Mapping

from .config import (DEFAULT_BUDGET_S, DEFAULT_PRESET, DEFAULT_QUERIES, DEFAULT_SAMPLES, DEFAULT_SIGMA_M, ModelConfig,
                     preset)
from .errors import ConfigError, shown
from .perceptions import perception_source
from .checking.fidelity import DEFAULT_CHECK, SelfCheck
from .query import QUERIES, QuerySpec
from .query.parameters import spec_parameters
from .sampling.montecarlo import check_budget
from .predict import AdaptiveStop, Request, check_ci_width  # noqa: F401 - Request re-exported
from .scene.launches import launch_spread
from .scene.properties import PropertySpread


def build_request(*, samples: int = DEFAULT_SAMPLES, sigma_m: float = DEFAULT_SIGMA_M,
                  phi_m_s2: Iterable[float] = (0.0,), force_direction_deg: float | None = None, mu: float | None = None,
                  ground_truth: bool = False, perception: str = "gaussian", vision=None,
                  queries: Iterable[str] = DEFAULT_QUERIES, contact: Iterable[tuple[str, str]] = (),
                  preset_name: str = DEFAULT_PRESET, horizon_s: float | None = None, until_rest: bool = False,
                  seed: int = 0, ci_width: float | None = None, deadline_s: float | None = None, batch_size: int = 4,
                  budget_s: float | None = DEFAULT_BUDGET_S, self_check: bool = True,
                  verify_samples: int = DEFAULT_CHECK.verify_samples, always_verify: bool = DEFAULT_CHECK.always_verify,
                  query_parameters: Mapping[str, Any] | None = None, mass_log_sd: float = 0.0,
                  friction_log_sd: float = 0.0, restitution_half_width: float = 0.0, launch_speed_log_sd: float = 0.0,
                  launch_direction_sd_deg: float = 0.0) -> Request:
    """The request these inputs ask for, or a ConfigError naming the engine's field.

    ``ground_truth``: sigma = phi = 0 and no body's own noise (the scene as given, one rollout).
    ``contact``: (A, B) pairs; giving any adds the contact query. ``horizon_s`` None and
    ``force_direction_deg`` None: the preset's horizon, any push direction. ``query_parameters``:
    queries' own parameters by name (``"<query>.<field>"``, ``query.parameters``); those of queries
    not asked are left out. ``mass_log_sd``, ``friction_log_sd``, ``restitution_half_width``: the
    model-wide priors of every value a scene gives exactly (``scene.properties.PropertySpread``; 0: off).
    ``launch_speed_log_sd``, ``launch_direction_sd_deg``: noise on what moves at t = 0
    (``scene.launches.LaunchSpread``; 0: off).
    """
    if ground_truth and perception_source(perception).posterior:
        raise ConfigError("ground_truth", f"takes the scene exactly as given, but perception {perception} draws it from "
                                          "a posterior; ask the ground truth with perception gaussian")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError("seed", f"must be an integer >= 0, got {shown(seed)}")
    if force_direction_deg is not None and not math.isfinite(force_direction_deg):
        raise ConfigError("force_direction_rad", f"must be finite degrees (or none: any direction), got "
                                                 f"{shown(force_direction_deg)}")
    model = ModelConfig(sigma_m=0.0 if ground_truth else sigma_m,
                        phi_m_s2=(0.0,) if ground_truth else tuple(phi_m_s2),
                        force_direction_rad=None if force_direction_deg is None else math.radians(force_direction_deg),
                        mu=mu, samples=samples, perception=perception, vision=vision, object_noise=not ground_truth,
                        property_spread=None if ground_truth else
                        property_spread(mass_log_sd, friction_log_sd, restitution_half_width),
                        launch_spread=None if ground_truth else
                        launch_spread(launch_speed_log_sd, _radians(launch_direction_sd_deg, "launch_direction_sd_deg")))
    contact = tuple(contact)
    asked = frozenset(queries) | ({"contact"} if contact else set())
    query = QuerySpec(queries=asked, contact_pairs=contact,
                      parameters=spec_parameters(asked, query_parameters or {}) if isinstance(asked, frozenset)
                      and asked <= set(QUERIES) else ())
    settings = preset(preset_name)
    if horizon_s is not None:
        settings = settings.changed(horizon_s=horizon_s)
    if until_rest:
        settings = settings.changed(early_stop={"enabled": True})
    stop = None
    if ci_width is not None or deadline_s is not None:
        check_ci_width(ci_width, query)
        stop = AdaptiveStop(ci_width=ci_width, deadline_s=deadline_s, batch_size=batch_size)
    check_budget(budget_s)
    check = SelfCheck(enabled=bool(self_check), verify_samples=verify_samples, always_verify=always_verify)
    return Request(model=model, settings=settings, query=query, seed=seed, stop=stop, budget_s=budget_s, check=check)


def _radians(degrees: float, field: str) -> float:
    """An SD given in degrees, as radians (checked in the unit its user typed)."""
    if isinstance(degrees, bool) or not isinstance(degrees, (int, float)) or not 0 <= degrees <= 180:
        raise ConfigError(field, f"must be degrees in [0, 180] (0: exact), got {shown(degrees)}")
    return math.radians(degrees)


def property_spread(mass_log_sd: float, friction_log_sd: float, restitution_half_width: float) -> PropertySpread | None:
    """The model-wide priors, or None when all are off (so that a request without them is keyed,
    stored and answered exactly as before they existed)."""
    spread = PropertySpread(mass_log_sd, friction_log_sd, restitution_half_width)
    return None if spread == PropertySpread() else spread
