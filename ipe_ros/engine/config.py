"""Every input, preset, default and rule of the engine, validated on construction: one home for all.

The CLI, the node's parameters, the service and the message bridge take their defaults from here.

Units:
    sigma_m           standard deviation of the horizontal position noise, metres (paper: 0.2 block
                      short sides; 0.04 m for the 0.2 m blocks of the tower CSVs).
    phi_m_s2          magnitude(s) of the latent push, as the support's horizontal acceleration in
                      m/s^2, applied for ``push_duration_s`` (paper: 0.2 s). Several magnitudes are
                      each simulated for every sample and averaged (paper Exp. 5).
    force_direction_rad  cued push direction in the scene frame (0 = +x, counter-clockwise), or
                      None for a direction uniform over the circle.
    mu                heavy/light density ratio for boxes whose group is "heavy", or None to keep
                      the scene's own masses.

"Settings" in this package always means :class:`SimSettings`: how one rollout is integrated.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field
from typing import Any

from .scene import limits
from .scene.launches import LaunchSpread
from .scene.properties import PropertySpread
from .checks import at_most, boolean, integer, non_negative, positive
from .errors import ConfigError, shown
from .perceptions import perception_source
from .sim_groups import (CollapseSettings, DepenetrationSettings, EarlyStopSettings, SettlingSettings,  # noqa: F401
                         SolverSettings)

#: The paper's IPE, as the CLI, the node and the service answer by default: sigma = 0.2 block short
#: sides (0.04 m for 0.2 m blocks), k = 48 samples, the fall fraction, the probability that anything
#: falls (free: the same rollouts), the direction and the reach.
DEFAULT_SIGMA_M = 0.04
DEFAULT_SAMPLES = 48
DEFAULT_QUERIES: frozenset[str] = frozenset({"fall", "any_fall", "direction", "far"})
DEFAULT_PRESET = "default"
#: Wall seconds one prediction may take in the node and ``ipe predict`` (the paper's own settings
#: answer a 10-block tower at k = 48 in ~11 s on two workers).
DEFAULT_BUDGET_S = 60.0

#: The model's own density for light boxes when it applies mu (paper: "the model then used its
#: assumption about mu to set each block's individual mass density"); also the density the message
#: bridge gives boxes that arrive without a mass. 170 kg/m^3 gives the stimuli's 4.08 kg per
#: 0.2 x 0.6 x 0.2 m block; under gravity and a push given as an acceleration only the ratios of
#: masses shape the motion, so the value matters for scale only.
MODEL_LIGHT_DENSITY_KG_M3 = 170.0


def anytime_batch_size(workers: int) -> int:
    """Samples per batch of anytime sampling: two per worker keep every worker busy between checks."""
    return 2 * max(1, workers)


def default_workers() -> int:
    """Worker processes when none are asked for: one per core, at most 8."""
    return max(1, min(os.cpu_count() or 1, 8))


#: the most samples one prediction may ask for (the CLI's and the node's range too: engine.inputs)
MAX_SAMPLES = 100_000


@dataclass(frozen=True)
class ModelConfig:
    """The IPE's inputs (paper SI, "Inputs") and its sample count k."""

    sigma_m: float = 0.0
    phi_m_s2: tuple[float, ...] = (0.0,)
    force_direction_rad: float | None = None
    cue_half_width_rad: float = math.pi / 4
    push_duration_s: float = 0.2
    mu: float | None = None
    samples: int = DEFAULT_SAMPLES
    #: where the k noisy scenes come from: a registered source (``perceptions.py``): "gaussian" (sigma,
    #: the paper's IPE), "vision" (the SI's Bayesian vision system: samples of an image posterior,
    #: ``vision`` its settings; sigma unused), "depth" (samples of the posterior given depth images,
    #: passed to ``predict`` as ``perceived``), or one registered since
    perception: str = "gaussian"
    vision: Any = None  # engine.vision.VisionSettings, or None for its defaults
    #: draw each body's own noise (``position_sigma_m``, ``yaw_sigma_rad``) where the scene gives it;
    #: False takes the scene exactly as given, as the ground truth (``--ground-truth``) must
    object_noise: bool = True
    #: model-wide priors over masses, frictions and restitutions (None: the scene's values, exact)
    property_spread: PropertySpread | None = field(default=None, metadata={"keyed": "when set"})
    #: model-wide noise on the speed and direction of what moves at t = 0 (None: as given)
    launch_spread: LaunchSpread | None = field(default=None, metadata={"keyed": "when set"})

    def __post_init__(self) -> None:
        non_negative(self.sigma_m, "sigma_m")
        at_most(self.sigma_m, "sigma_m", limits.MAX_SIGMA_M, "m (check the units)")
        if not isinstance(self.phi_m_s2, tuple) or not self.phi_m_s2:
            raise ConfigError("phi_m_s2", f"must be a non-empty tuple of accelerations, got {shown(self.phi_m_s2)}")
        for value in self.phi_m_s2:
            non_negative(value, "phi_m_s2")
            at_most(value, "phi_m_s2", limits.MAX_PHI_M_S2, "m/s^2 (10 g)")
        if self.force_direction_rad is not None and (
                isinstance(self.force_direction_rad, bool) or not math.isfinite(self.force_direction_rad)):
            raise ConfigError("force_direction_rad", f"must be a finite angle or None, got {shown(self.force_direction_rad)}")
        if not 0 <= self.cue_half_width_rad <= math.pi:
            raise ConfigError("cue_half_width_rad", f"must be in [0, pi], got {shown(self.cue_half_width_rad)}")
        positive(self.push_duration_s, "push_duration_s")
        if self.mu is not None:
            positive(self.mu, "mu")
            at_most(self.mu, "mu", limits.MAX_MASS_RATIO, "(the solver's mass-ratio limit)")
        integer(self.samples, "samples", 1, MAX_SAMPLES)
        boolean(self.object_noise, "object_noise")
        if self.launch_spread is not None and not isinstance(self.launch_spread, LaunchSpread):
            raise ConfigError("launch_spread", f"must be a LaunchSpread or None, got {shown(self.launch_spread)}")
        perception_source(self.perception)  # a ConfigError naming the choices

    @property
    def pushes(self) -> bool:
        return any(v > 0 for v in self.phi_m_s2)

    @property
    def is_deterministic(self) -> bool:
        """sigma = phi = 0 and no posterior to draw from: no noise of the model's own. Whether a
        prediction is deterministic also depends on the scene's per-body noise:
        ``perturb.is_deterministic``."""
        return self.sigma_m == 0 and not self.pushes and not perception_source(self.perception).posterior \
            and self.property_spread is None

#: The paper's IPE with the default sigma and k (phi = 0, the scene's own masses).
DEFAULT_MODEL = ModelConfig(sigma_m=DEFAULT_SIGMA_M, samples=DEFAULT_SAMPLES)


# --------------------------------------------------------------------------------------------
# simulation settings: one group per concern of the stepper (sim_groups.py), held by SimSettings

_GROUPS = {"solver": SolverSettings, "depenetration": DepenetrationSettings, "settling": SettlingSettings,
           "collapse": CollapseSettings, "early_stop": EarlyStopSettings}


@dataclass(frozen=True)
class SimSettings:
    """How each rollout is integrated: the step, the horizon, and one group per concern.

    time_step_s: the fine step; never more than ``max_step_fraction_of_time_scale`` of the bodies'
        time scale sqrt(size / g), so small bodies get finer steps (3 mm cubes sank through each
        other at 1/240 s; 0.03 leaves 0.2 m blocks at 1/240 s and gives 3 mm cubes ~0.5 ms).
    step_time_scale: which size that is. "thickness": each body's smallest extent (the time to fall
        its own thickness). "tipping": its middle extent, the shortest lever it can tip or roll about
        (a plate tips about its width whether it lies flat or stands on edge; a rod rolls about its
        width); the travel limit's substeps still follow the smallest extent. Every preset follows
        the thickness: "tipping" made `default` 1.1x faster on the zoo's held-out seed and missed
        the bars of dominoes, strike and plates (a plate resting on its edge rocks on its thickness,
        and slid off it more often); household ran 1.4x slower unchecked, 6% of its rollouts' collapse
        steps undone against 1% (benchmarks/HISTORY.md, issue 75).
    horizon_s: simulated time of a rollout (the paper's 2 s), unless early termination ends it or
        the scene asks for its own.
    max_travel_fraction: the travel limit: no body may move more than this fraction of the smallest
        extent in one step. Checked at every look (from the fastest corner, plus what gravity adds
        until the next look): a fast body gets substeps, at most ``max_substeps`` per step, and
        collapse steps are never coarser than this. Contacts are found as far ahead as the fastest
        body travels in a step (Bullet's contact breaking threshold, between ``min_contact_fraction``
        of the smallest extent and the travel limit), so a body that reaches a surface within one
        step already has a contact with it there: found only within Bullet's fixed 2 cm, a box
        landing at a coarse step sank 20% of its size into the floor and was still there at the
        horizon; found 10 cm ahead while a tower stands, resting blocks held one of the authors'
        towers up that their simulation topples.
    rigid_when_unhealthy: a rollout in multibodies that ends unhealthy (a body more than 5% of its
        smallest extent inside another, energy gained beyond 1% of the scene's scale, or a physics
        error) is rerun in plain rigid bodies at the same step and iterations, and the rerun is the
        sample (``SampleOutcome.rerun_rigid`` says why). pybullet's multibodies let a thin rod
        against a mesh's convex parts gain up to 33x a scene's energy (a 4 mm ladle in a tipping mug:
        28 of 32 `paper` rollouts), where plain rigid bodies, at the same step, gain none; the
        paper's own engine, ODE, integrates plain rigid bodies (benchmarks/results/meshes).
    islands: groups of bodies that nothing brings together are simulated apart, each in a world of
        its own with its own step (its smallest body's, not the scene's) and its own end at rest;
        where two could have met (each island's reach, read at every look, and the bodies' own
        shapes where their bounding boxes overlap), the sample is simulated
        again as one world (simulation/islands.py). Only groups that step at least twice as coarse
        apart are kept apart (``islands.by_step``); the others share a world. Step watches (contact,
        event queries) and "will anything fall?" keep one world.
    """

    name: str
    time_step_s: float
    horizon_s: float
    solver: SolverSettings
    max_step_fraction_of_time_scale: float = 0.03
    max_travel_fraction: float = 0.5
    max_substeps: int = 32
    min_contact_fraction: float = 0.1
    depenetration: DepenetrationSettings = DepenetrationSettings()
    settling: SettlingSettings = SettlingSettings()
    collapse: CollapseSettings = CollapseSettings()
    early_stop: EarlyStopSettings = EarlyStopSettings()
    #: part of a stored result's key only when set, so that results stored before it keep their keys
    rigid_when_unhealthy: bool = field(default=False, metadata={"keyed": "when set"})
    islands: bool = field(default=False, metadata={"keyed": "when set"})
    step_time_scale: str = field(default="thickness", metadata={"keyed": "when set"})

    def __post_init__(self) -> None:
        positive(self.time_step_s, "time_step_s")
        boolean(self.rigid_when_unhealthy, "rigid_when_unhealthy")
        boolean(self.islands, "islands")
        positive(self.horizon_s, "horizon_s")
        positive(self.max_step_fraction_of_time_scale, "max_step_fraction_of_time_scale")
        positive(self.max_travel_fraction, "max_travel_fraction")
        positive(self.min_contact_fraction, "min_contact_fraction")
        integer(self.max_substeps, "max_substeps", 1, 1000)
        if self.step_time_scale not in STEP_TIME_SCALES:
            raise ConfigError("step_time_scale", f"unknown {shown(self.step_time_scale)}; choose one of "
                                                 f"{', '.join(STEP_TIME_SCALES)}")
        if self.time_step_s > self.horizon_s:
            raise ConfigError("time_step_s", "must not exceed horizon_s")
        for group, kind in _GROUPS.items():
            if not isinstance(getattr(self, group), kind):
                raise ConfigError(group, f"must be a {kind.__name__}, got {shown(getattr(self, group))}")

    def time_scale_extent_m(self, extents_m) -> float:
        """The size whose fall time bounds the step, among bodies of ``extents_m`` (each body's
        three; see ``step_time_scale``)."""
        which = 0 if self.step_time_scale == "thickness" else 1
        return min(sorted(e)[which] for e in extents_m)

    def time_step_for(self, scale_m: float, gravity_m_s2: float, fastest_m_s: float = 0.0,
                      time_scale_m: float | None = None) -> float:
        """The step for a scene whose smallest extent is ``scale_m`` and whose fastest body starts
        at ``fastest_m_s`` (see ``time_step_s`` and ``max_travel_fraction``); ``time_scale_m``: the
        size of ``time_scale_extent_m`` (default ``scale_m``)."""
        size = scale_m if time_scale_m is None else time_scale_m
        step = min(self.time_step_s, self.max_step_fraction_of_time_scale * math.sqrt(size / gravity_m_s2))
        if fastest_m_s > 0:
            step = min(step, self.max_travel_fraction * scale_m / fastest_m_s)
        return step

    def iterations_for(self, mass_ratio: float, iterations: int | None = None) -> int:
        """Solver iterations for a scene whose heaviest body outweighs its lightest ``mass_ratio`` times."""
        base = self.solver.iterations if iterations is None else iterations
        needed = math.ceil(self.solver.iterations_per_mass_ratio * mass_ratio)
        return max(base, min(needed, self.solver.max_iterations))

    def horizon_for(self, scene_horizon_s: float | None) -> float:
        """The scene's own horizon when it gives one, else these settings'."""
        return self.horizon_s if scene_horizon_s is None else scene_horizon_s

    def changed(self, name: str | None = None, **changes: Any) -> SimSettings:
        """A copy with some fields changed; a group takes a dict of its own fields.

        ``preset("default").changed("default-50it", solver={"iterations": 50}, horizon_s=1.0)``
        """
        top: dict[str, Any] = {} if name is None else {"name": name}
        for key, value in changes.items():
            if key in _GROUPS and isinstance(value, dict):
                try:
                    value = dataclasses.replace(getattr(self, key), **value)
                except TypeError as exc:
                    raise ConfigError(key, f"{exc}; its fields are "
                                           f"{', '.join(f.name for f in dataclasses.fields(_GROUPS[key]))}") from None
            elif key not in {f.name for f in dataclasses.fields(self)}:
                raise ConfigError(key, "not a field of SimSettings")
            top[key] = value
        return dataclasses.replace(self, **top)


#: what ``SimSettings.step_time_scale`` may name
STEP_TIME_SCALES = ("thickness", "tipping")


PRESETS: dict[str, SimSettings] = {
    # The paper's settings: 1 ms steps for the full 2 s, a fully converged solver, no shortcuts.
    "paper": SimSettings(name="paper", time_step_s=0.001, horizon_s=2.0, solver=SolverSettings(iterations=50, direct_solver_for_impacts_only=True, bounce_from_touch=True),
                         rigid_when_unhealthy=True),
    # 1 ms / 2 s with 20 solver iterations: close to `paper` (mean |dFF| ~0.006) at ~1.8x its speed.
    "accurate": SimSettings(name="accurate", time_step_s=0.001, horizon_s=2.0, solver=SolverSettings(iterations=20, direct_solver_for_impacts_only=True, bounce_from_touch=True),
                            rigid_when_unhealthy=True),
    # 1/240 s steps (1/233 s for 0.2 m blocks, by the size cap), plain rigid bodies with a full warm
    # start, up to 100 solver iterations to a residual of 3e-6 (a looser 1e-5 topples a delicately
    # balanced tower that stands), the first 0.1 s in half steps, and rollouts that end once
    # everything has been at rest (and slowing down) for 0.2 s.
    "fine": SimSettings(name="fine", time_step_s=1 / 240, horizon_s=2.0,
                        solver=SolverSettings(iterations=100, residual_threshold=3e-6, warm_start_factor=1.0,
                                              maximal_coordinates=True, direct_solver_for_impacts_only=True, bounce_from_touch=True),
                        settling=SettlingSettings(duration_s=0.1, substeps=2),
                        early_stop=EarlyStopSettings(enabled=True)),
    # The default: `fine`'s solver at 1/180 s steps, to a residual of 1e-5 (at these steps the
    # delicately balanced tower stands to 1.25e-5), until something falls, then up to 4x coarser
    # collapse steps at 50 solver iterations and `fine`'s residual, no body travelling more than a
    # quarter of the smallest extent per step (a collapse's statistics, not its every contact, are
    # what the answer needs); settling as `fine`; a 0.15 s rest window from 0.2 s on, "at rest" read as slower than 0.4
    # sizes/s and 0.4 rad/s and not speeding up; groups that nothing brings together and that step at
    # least twice as coarse apart simulated apart (islands); the direct solver only for bounces of 0.1
    # and more or bodies thrown in at 1 m/s and more, and thin boxes on it in multibodies, which hold
    # their friction (SolverSettings: direct_solver_min_restitution, direct_solver_from_speed_m_s,
    # multibodies_from_aspect). Each of these is the coarsest setting
    # that keeps the hard cases (tests/test_hard_cases.py) and the authors' outcomes
    # (tests/test_paper_data.py); speed and accuracy against `paper` in benchmarks/HISTORY.md.
    "default": SimSettings(name="default", time_step_s=1 / 180, horizon_s=2.0, max_step_fraction_of_time_scale=0.04,
                           solver=SolverSettings(iterations=100, residual_threshold=1e-5, warm_start_factor=1.0,
                                                 maximal_coordinates=True, multibodies_from_aspect=10.0,
                                                 direct_solver_min_restitution=0.1, direct_solver_from_speed_m_s=1.0,
                                                 direct_solver_for_impacts_only=True, bounce_from_touch=True),
                           settling=SettlingSettings(duration_s=0.1, substeps=2),
                           collapse=CollapseSettings(step_factor=4, solver_iterations=50, end_substeps=1,
                                                     max_travel_fraction=0.25, end_travel_fraction=0.05,
                                                     anchor_after_steps=300, residual_threshold=3e-6),
                           early_stop=EarlyStopSettings(enabled=True, speed_sizes_per_s=0.4, angular_rad_s=0.4,
                                                        duration_s=0.15, min_time_s=0.2),
                           islands=True),
}


def preset(name: str) -> SimSettings:
    try:
        return PRESETS[name]
    except KeyError:
        raise ConfigError("preset", f"unknown preset {shown(name)}; choose one of {', '.join(PRESETS)}") from None
