"""``infer``: the posterior over an observation's unknown properties, by the IPE's own rollouts.

Each candidate is a set of property values (and, for an object whose initial velocity the scene left
out, a velocity: a nuisance drawn around the frames' own estimate and integrated over); its rollout
is weighed by how likely the frames are given it (``likelihood``: the tracker's noise and the
physics' error); the sampler is ``amis``. The answer says per unknown the posterior mean, median,
90% interval and effective sample size, P(m_a > m_b) for every pair of mass unknowns, how far the
best rollout stays from the frames, and the scene with the posterior medians in place. An
observation no candidate reproduces is answered ``consistent: false``, never with a posterior.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from dataclasses import dataclass

import numpy as np

from .. import checks
from ..config import DEFAULT_PRESET, CollapseSettings, SimSettings, preset
from ..errors import ConfigError
from ..sampling.montecarlo import MapFn, MonteCarlo, check_seed
from ..scene.bodies import Scene, TimedPush
from ..scene.format import scene_to_dict
from .amis import AmisResult, AmisSettings, amis, grid
from .likelihood import CONSISTENT_WITHIN_SD, MODEL_ERROR_GRID, Track, track
from .observation import Observation, Unknown
from .particle import ParticleOutcome, ParticleTask, lost_particle, run_particle, with_values
from ..scene.properties import Normal, posterior_prior, with_properties

#: A property that reproduces an observation in this engine differs from the world's (or another
#: engine's) by a factor no trajectory can show, since the property itself absorbs it. The answer's
#: values are therefore the engine's times exp(N(0, sd^2)), sd per property (log scale). Restitution
#: and friction fitted (session 46) to observations made at `paper` and by MuJoCo
#: (benchmarks/results/inference: 90% intervals then cover 90-94% of pybullet's and 90-100% of
#: MuJoCo's; at the session 45 values, 3% and 0.5%, 98-100%); the mass's stated: the collisions'
#: coverage does not move with it (1% or 2%: 100%, held by the replicates' spread).
ENGINE_DISCREPANCY_LOG_SD = {"restitution": 0.015, "mass_kg": 0.02, "friction": 0.0025}
DISCREPANCY_COPIES = 16
#: equally weighted draws an answer keeps for plots
DRAWS = 400
#: the frames within this much of t = 0 estimate an unknown initial velocity
VELOCITY_WINDOW_S = 0.15


@dataclass(frozen=True)
class InferSettings:
    #: the preset (or a request's settings) candidates are rolled out at, without its collapse steps
    #: (``trajectory_settings``)
    simulation: SimSettings = preset(DEFAULT_PRESET)
    seed: int = 0
    sampler: AmisSettings = AmisSettings()
    #: the physics' own error as a fraction of the distance travelled (likelihood.py); None: inferred
    #: with the properties (marginalised over MODEL_ERROR_GRID)
    model_error_fraction: float | None = None
    #: the t = 0 poses' noise integrated over (a nuisance: chaos must not let one lucky rollout
    #: decide), horizontal SD in metres; None: the observation's position_sd_m
    initial_sd_m: float | None = None
    #: a plain grid of this many points per unknown instead of AMIS (the benchmark's baseline; no
    #: unknown initial velocities)
    grid_points: int | None = None
    #: the answer's values are the world's, the engine's own spread by ENGINE_DISCREPANCY_LOG_SD
    engine_discrepancy: bool = True
    #: the most rollouts per candidate, each from its own noisy start (two where two agree)
    replicates: int = 4
    budget_s: float | None = 60.0

    def __post_init__(self) -> None:
        if not isinstance(self.simulation, SimSettings):
            raise ConfigError("simulation", f"must be a preset's settings (config.preset(NAME)), got "
                                            f"{type(self.simulation).__name__}")
        check_seed(self.seed)
        if self.model_error_fraction is not None:
            checks.non_negative(self.model_error_fraction, "model_error_fraction")
            checks.at_most(self.model_error_fraction, "model_error_fraction", 1.0,
                           "(a fraction of the distance travelled)")
        checks.integer(self.sampler.particles_per_round, "particles_per_round", 4, 10_000)
        checks.integer(self.sampler.max_rounds, "max_rounds", 1, 100)
        checks.integer(self.replicates, "replicates", 1, 64)
        if self.initial_sd_m is not None:
            checks.non_negative(self.initial_sd_m, "initial_sd_m")
            checks.at_most(self.initial_sd_m, "initial_sd_m", 0.1, "m (a tracker's error at t = 0)")


@dataclass(frozen=True)
class Estimate:
    label: str  # "box1.mass_kg", "group:red.mass_kg", "support.friction"
    property: str
    mean: float
    median: float
    low_90: float
    high_90: float
    ess: float


@dataclass(frozen=True)
class MassPair:
    """Two mass unknowns compared: P(m_a > m_b) and the ratio m_a / m_b (identifiable without any
    known impulse, where the masses themselves are not)."""

    a: str
    b: str
    p_a_heavier: float
    ratio_median: float
    ratio_low_90: float
    ratio_high_90: float


@dataclass(frozen=True)
class Inference:
    scene_name: str
    consistent: bool
    message: str
    estimates: tuple[Estimate, ...]
    heavier: tuple["MassPair", ...]
    worst_residual_m: float  # the best rollout's farthest frame
    worst_t_s: float
    worst_object: str
    candidates: int
    failed: int
    rounds: int
    ess: float
    stopped_by: str
    likelihood_power: float
    elapsed_s: float
    refined_scene: Scene | None
    settings: InferSettings
    #: the physics' error inferred with the properties (None where the settings fixed it)
    model_error: Estimate | None = None
    #: equally weighted draws of the unknowns (DRAWS x unknowns), the world's values: for plots
    draws: np.ndarray | None = dataclasses.field(default=None, compare=False, repr=False)

    def estimate(self, label: str) -> Estimate:
        return next(e for e in self.estimates if e.label == label)

    def to_dict(self) -> dict:
        return {"scene": self.scene_name, "consistent": self.consistent, "message": self.message,
                "unknowns": {e.label: {"mean": e.mean, "median": e.median, "interval_90": [e.low_90, e.high_90],
                                       "ess": round(e.ess, 1)} for e in self.estimates},
                "mass_pairs": [{"a": m.a, "b": m.b, "p_a_heavier": round(m.p_a_heavier, 4),
                                "ratio_median": m.ratio_median, "ratio_interval_90": [m.ratio_low_90, m.ratio_high_90]}
                               for m in self.heavier],
                "check": {"worst_residual_mm": round(1000 * self.worst_residual_m, 2), "t_s": self.worst_t_s,
                          "object": self.worst_object},
                "candidates": self.candidates, "failed": self.failed, "rounds": self.rounds, "ess": round(self.ess, 1),
                "likelihood_power": round(self.likelihood_power, 4), "stopped_by": self.stopped_by, "elapsed_s": round(self.elapsed_s, 3),
                "model_error_fraction": None if self.model_error is None else {
                    "median": self.model_error.median, "interval_90": [self.model_error.low_90, self.model_error.high_90]},
                "settings": {"preset": self.settings.simulation.name, "seed": self.settings.seed,
                             "model_error_fraction": self.settings.model_error_fraction,
                             "particles_per_round": self.settings.sampler.particles_per_round,
                             "max_rounds": self.settings.sampler.max_rounds,
                             "target_ess": self.settings.sampler.target_ess, "budget_s": self.settings.budget_s,
                             "initial_sd_m": self.settings.initial_sd_m, "replicates": self.settings.replicates,
                             "engine_discrepancy": self.settings.engine_discrepancy},
                "refined_scene": None if self.refined_scene is None else scene_to_dict(self.refined_scene)}


def trajectory_settings(settings: SimSettings) -> SimSettings:
    """``settings`` for following trajectories: without its collapse steps, which keep a collapse's
    statistics but not its path (under `default`, a tipping tower's top block 35 mm from `paper`
    0.13 s in; 1.7-4.8 SDs at the truth without them, 8.2 with)."""
    return dataclasses.replace(settings, collapse=CollapseSettings()) if settings.collapse.enabled else settings


def velocity_prior(observation: Observation, name: str) -> list[Normal]:
    """An unknown initial velocity's prior, per axis: N(the frames' estimate, a wide SD). The estimate
    fits p(t) = p0 + v t + a t^2 / 2 (p0 is the scene's exact pose) to the frames within
    VELOCITY_WINDOW_S (at least the first two); the SD is 3x the fit's noise SD plus 20% of the
    estimate and 0.05 m/s, since friction or a contact may already act within the window."""
    times, positions, _ = observation.track(name)
    origin = np.asarray(next(b.position_m for b in observation.scene.objects if b.name == name), float)
    keep = max(2, int(np.sum(times <= VELOCITY_WINDOW_S)))
    t, p = times[:keep], positions[:keep] - origin
    design = np.stack([t, t * t / 2], axis=1) if keep >= 3 else t[:, None]
    solution, *_ = np.linalg.lstsq(design, p, rcond=None)
    v = solution[0]
    noise_sd = observation.position_sd_m * math.sqrt(float(np.linalg.inv(design.T @ design)[0, 0]))
    return [Normal(float(v[axis]), 3 * noise_sd + 0.2 * abs(float(v[axis])) + 0.05) for axis in range(3)]


def infer(observation: Observation, settings: InferSettings = InferSettings(), map_fn: MapFn | None = None) -> Inference:
    started = time.perf_counter()
    unknowns = observation.unknowns
    priors = [u.prior for u in unknowns]
    for name in observation.unknown_velocity:  # then each unknown initial velocity's three axes
        priors.extend(velocity_prior(observation, name))
    scene = dataclasses.replace(observation.scene, horizon_s=observation.window_s)
    sim = trajectory_settings(settings.simulation)
    tracks = _tracks(observation)
    errors = MODEL_ERROR_GRID if settings.model_error_fraction is None else (settings.model_error_fraction,)
    initial_sd = observation.position_sd_m if settings.initial_sd_m is None else settings.initial_sd_m
    if len(scene.dynamic_objects) == 1:
        initial_sd = 0.0  # a lone object on a flat support is not chaotic: one exact rollout per candidate

    def candidate(z: np.ndarray) -> Scene:
        values = [p.value(zj) for p, zj in zip(priors, z)]
        assigned = {(body, u.property): float(x) for u, x in zip(unknowns, values) for body in u.applies_to(scene)}
        velocities, at = {}, len(unknowns)
        for name in observation.unknown_velocity:
            velocities[name] = np.array(values[at:at + 3], float)
            at += 3
        return _pushed(with_values(scene, assigned, {}), observation, velocities)

    def make_task(i: int, z: np.ndarray) -> ParticleTask:
        return ParticleTask(i, candidate(z), sim, tracks, observation.yaw_sd_rad, errors,
                            initial_sd, settings.replicates, np.random.SeedSequence(settings.seed, spawn_key=(1, i)))

    def read(outcome: ParticleOutcome) -> float | None:
        if outcome.budget_stopped:
            return None
        return outcome.fit.log_likelihood if outcome.ok else -math.inf

    loop = MonteCarlo(run_particle, lost_particle, map_fn, settings.budget_s)
    if settings.grid_points is not None:
        if observation.unknown_velocity:
            raise ConfigError("grid_points", "a grid takes no unknown initial velocities; give them in the scene")
        plan = grid(priors, make_task, read, settings.grid_points)
    else:
        plan = amis(priors, make_task, read, settings.seed, settings.sampler)
    result: AmisResult = loop.drive(plan)
    return _answer(observation, settings, result, unknowns, priors, time.perf_counter() - started)


def observed_rollout_scene(observation: Observation, scene: Scene) -> Scene:
    """``scene`` (the observation's, or a refined one) as the observation rolled it out: its window as
    the horizon, the pushes applied, unknown initial velocities at the frames' estimates."""
    velocities = {name: [n.mean for n in velocity_prior(observation, name)] for name in observation.unknown_velocity}
    return _pushed(dataclasses.replace(scene, horizon_s=observation.window_s), observation, velocities)


def _pushed(scene: Scene, observation: Observation, velocities: dict) -> Scene:
    """The scene with each nuisance-moving object's initial velocity (``velocities``, drawn) and the
    robot's pushes: at t = 0 added to the initial velocity, later ones as the scene's timed pushes
    (an impulse over the object's mass, this candidate's)."""
    out = {name: np.asarray(v, float) for name, v in velocities.items()}
    bodies = {b.name: b for b in scene.objects}
    later = []
    for push in observation.actions:
        body = bodies[push.object]
        change = np.array(push.velocity_m_s if push.velocity_m_s is not None
                          else np.asarray(push.impulse_N_s) / body.resolved_mass_kg, float)
        change = np.array([change[0], change[1], 0.0])
        if push.at_s > 0:
            later.append(TimedPush(push.object, push.at_s, tuple(float(c) for c in change)))
        else:
            out[push.object] = out.get(push.object, np.asarray(body.linear_velocity_m_s, float)) + change
    scene = with_values(scene, {}, out)
    return dataclasses.replace(scene, pushes=tuple(sorted(later, key=lambda p: p.at_s))) if later else scene


def _tracks(observation: Observation) -> tuple[Track, ...]:
    out = []
    for body in observation.scene.dynamic_objects:
        times, positions, orientations = observation.track(body.name)
        if len(times):
            out.append(track(body.name, times, positions, orientations, observation.position_sd_m))
    return tuple(out)


def _summary(label: str, prop: str, values: np.ndarray, weights: np.ndarray, ess: float) -> Estimate:
    """The weighted values' mean, median and 90% interval."""
    return Estimate(label, prop, float(weights @ values / weights.sum()), _weighted_quantile(values, weights, 0.5),
                    _weighted_quantile(values, weights, 0.05), _weighted_quantile(values, weights, 0.95), ess)


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][min(np.searchsorted(cumulative, q * cumulative[-1]), len(values) - 1)])


def _in_the_world(values: np.ndarray, w: np.ndarray, unknowns, settings: InferSettings) -> tuple[np.ndarray, np.ndarray]:
    """The engine's posterior values as the world's: each candidate spread into DISCREPANCY_COPIES
    copies, each property times exp(N(0, ENGINE_DISCREPANCY_LOG_SD[property]^2)) (restitutions kept
    <= 1). Off (``engine_discrepancy=False``): the engine's own values."""
    if not settings.engine_discrepancy or not len(values):
        return values, w
    rng = np.random.default_rng(np.random.SeedSequence(settings.seed, spawn_key=(2,)))
    sd = np.array([ENGINE_DISCREPANCY_LOG_SD[u.property] for u in unknowns])
    spread = values[None] * np.exp(sd * rng.standard_normal((DISCREPANCY_COPIES, *values.shape)))
    restitution = np.array([u.property == "restitution" for u in unknowns])
    spread[..., restitution] = np.minimum(spread[..., restitution], 1.0)
    return spread.reshape(-1, values.shape[1]), np.tile(w, DISCREPANCY_COPIES)


def _model_error(result: AmisResult, w: np.ndarray, usable: np.ndarray) -> Estimate:
    """The physics' error's posterior on its grid: each candidate's weight shared among the grid's
    fractions in proportion to its likelihood at each."""
    mass = np.zeros(len(MODEL_ERROR_GRID))
    for weight, outcome in zip(w[usable], [o for o, u in zip(result.outcomes, usable) if u]):
        by_error = np.asarray(outcome.fit.log_likelihood_by_error) * result.likelihood_power
        share = np.exp(by_error - by_error.max())
        mass += weight * share / share.sum()
    return _summary("model_error_fraction", "model_error_fraction", np.asarray(MODEL_ERROR_GRID), mass, result.ess)


def _pair(a: str, b: str, mass_a: np.ndarray, mass_b: np.ndarray, w: np.ndarray) -> MassPair:
    ratio = mass_a / mass_b
    return MassPair(a, b, float(w @ (mass_a > mass_b) / w.sum()), _weighted_quantile(ratio, w, 0.5),
                    _weighted_quantile(ratio, w, 0.05), _weighted_quantile(ratio, w, 0.95))


def posterior_priors(unknowns, estimates, scene: Scene) -> dict:
    """(owner, property) -> the posterior as a prior (``posterior_prior``), for each owner an
    unknown applies to: a refined scene's predictions then carry what is still uncertain. A group's
    members draw independently there (the scene format has no shared draw)."""
    out = {}
    for u, e in zip(unknowns, estimates):
        prior = posterior_prior(u.property, e.median, e.low_90, e.high_90)
        if prior is not None:
            out.update({(owner, u.property): prior for owner in u.applies_to(scene)})
    return out


def _answer(observation: Observation, settings: InferSettings, result: AmisResult, unknowns: tuple[Unknown, ...],
            priors: list, elapsed_s: float) -> Inference:
    ok = [o for o in result.outcomes if o.ok]
    failed = sum(1 for o in result.outcomes if not o.ok and not o.budget_stopped)
    common = dict(scene_name=observation.scene.name, candidates=len(result.outcomes), failed=failed,
                  rounds=result.rounds, ess=result.ess, stopped_by=result.stopped_by,
                  likelihood_power=result.likelihood_power, elapsed_s=elapsed_s,
                  settings=settings)
    if not ok:
        raise ConfigError("budget_s" if result.stopped_by == "budget" else "observation",
                          "no candidate's rollout finished: raise the budget" if result.stopped_by == "budget"
                          else f"every rollout failed ({result.outcomes[0].error}); check the scene")
    best = max(ok, key=lambda o: o.fit.log_likelihood).fit
    if best.worst_sds > CONSISTENT_WITHIN_SD:
        message = (f"no property values reproduce the observation: worst residual {1000 * best.worst_residual_m:.1f} mm "
                   f"at t = {best.worst_t_s:g} s on {best.worst_object}")
        return Inference(consistent=False, message=message, estimates=(), heavier=(), worst_residual_m=best.worst_residual_m,
                         worst_t_s=best.worst_t_s, worst_object=best.worst_object, refined_scene=None, **common)
    w = result.weights
    usable = np.isfinite(result.log_weights)
    model_error = None if settings.model_error_fraction is not None else _model_error(result, w, usable)
    values = np.stack([p.value(result.coordinates[usable, j]) for j, p in enumerate(priors[:len(unknowns)])], axis=1)
    values, w = _in_the_world(values, w[usable], unknowns, settings)
    estimates = [_summary(u.label, u.property, values[:, j], w, result.ess) for j, u in enumerate(unknowns)]
    masses = [j for j, u in enumerate(unknowns) if u.property == "mass_kg"]
    heavier = tuple(_pair(unknowns[a].label, unknowns[b].label, values[:, a], values[:, b], w)
                    for a, b in itertools.combinations(masses, 2))
    chosen = np.random.default_rng(np.random.SeedSequence(settings.seed, spawn_key=(3,))).choice(
        len(w), size=DRAWS, p=w / w.sum())
    medians = {(body, u.property): e.median for u, e in zip(unknowns, estimates) for body in u.applies_to(observation.scene)}
    refined = with_properties(observation.scene, medians, posterior_priors(unknowns, estimates, observation.scene))
    message = (f"{len(estimates)} unknown(s) from {len(result.outcomes)} rollouts; effective sample size "
               f"{result.ess:.0f}" + ("; stopped by the budget: a partial answer" if result.stopped_by == "budget" else "")
               + (f"; the frames weighed at power {result.likelihood_power:.2g} (too few rollouts near the best "
                  "fit, or chaotic motion, to weigh them fully)" if result.likelihood_power < 1 else ""))
    return Inference(consistent=True, message=message, estimates=tuple(estimates), heavier=heavier,
                     worst_residual_m=best.worst_residual_m, worst_t_s=best.worst_t_s, worst_object=best.worst_object,
                     refined_scene=refined, model_error=model_error, draws=values[chosen], **common)
