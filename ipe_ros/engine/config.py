"""Model inputs (sigma, phi, mu), simulation presets and query selection, validated on construction.

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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import ConfigError

#: Every query the engine can answer. ``fall`` includes per-object fall probabilities.
#: fall: expected fraction of boxes that fall; any_fall: probability that anything falls (yes/no,
#: its rollouts stop at the first fall); direction, far: where they fall; bump: what falls off a table.
ALL_QUERIES = ("fall", "any_fall", "direction", "far", "bump")


def _positive(value: float, field: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value <= 0:
        raise ConfigError(field, f"must be a finite number > 0, got {value!r}")


def _non_negative(value: float, field: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value < 0:
        raise ConfigError(field, f"must be a finite number >= 0, got {value!r}")


@dataclass(frozen=True)
class ModelConfig:
    """The IPE's inputs (paper SI, "Inputs") and its sample count k."""

    sigma_m: float = 0.0
    phi_m_s2: tuple[float, ...] = (0.0,)
    force_direction_rad: float | None = None
    cue_half_width_rad: float = math.pi / 4
    push_duration_s: float = 0.2
    mu: float | None = None
    samples: int = 48

    def __post_init__(self) -> None:
        _non_negative(self.sigma_m, "sigma_m")
        if not isinstance(self.phi_m_s2, tuple) or not self.phi_m_s2:
            raise ConfigError("phi_m_s2", f"must be a non-empty tuple of accelerations, got {self.phi_m_s2!r}")
        for value in self.phi_m_s2:
            _non_negative(value, "phi_m_s2")
        if self.force_direction_rad is not None and (
                isinstance(self.force_direction_rad, bool) or not math.isfinite(self.force_direction_rad)):
            raise ConfigError("force_direction_rad", f"must be a finite angle or None, got {self.force_direction_rad!r}")
        if not 0 <= self.cue_half_width_rad <= math.pi:
            raise ConfigError("cue_half_width_rad", f"must be in [0, pi], got {self.cue_half_width_rad!r}")
        _positive(self.push_duration_s, "push_duration_s")
        if self.mu is not None:
            _positive(self.mu, "mu")
        if isinstance(self.samples, bool) or not isinstance(self.samples, int) or not 1 <= self.samples <= 100_000:
            raise ConfigError("samples", f"must be an integer in [1, 100000], got {self.samples!r}")

    @property
    def pushes(self) -> bool:
        return any(v > 0 for v in self.phi_m_s2)

    @property
    def is_deterministic(self) -> bool:
        """sigma = phi = 0: the ground-truth model; one rollout says everything."""
        return self.sigma_m == 0 and not self.pushes


@dataclass(frozen=True)
class SimSettings:
    """How each rollout is integrated. ``paper`` reproduces the authors' 1 ms / 2 s settings."""

    name: str
    time_step_s: float
    horizon_s: float
    solver_iterations: int
    #: pybullet stops iterating the solver once the residual is below this (scaled by scene size).
    solver_residual_threshold: float = 1e-7
    #: Depenetration: stop once no pair of boxes overlaps by more than this fraction of the
    #: smallest box extent.
    depenetration_tolerance_fraction: float = 1e-3
    depenetration_max_iterations: int = 200
    #: pybullet's warm start of the solver from the last step's impulses (its default is 0.85);
    #: 1.0 carries resting contacts over fully, which keeps stacks quiet at coarse steps.
    warm_start_factor: float = 0.85
    #: Boxes as plain rigid bodies (pybullet's ``useMaximalCoordinates``) instead of one-link
    #: multibodies: the classic sequential-impulse solver, cheaper per contact for free boxes.
    maximal_coordinates: bool = False
    #: Early termination: end a rollout once every dynamic box has been at rest for
    #: ``rest_duration_s`` (after the push and ``rest_min_time_s``): nothing can move any more.
    #: When ``fall`` is the only query, a box that has already fallen counts as settled too. The
    #: motion must also not have grown over the window: a tower just starting to tip is slow but
    #: accelerating (ending it at 0.5 s kept a tower standing that the authors' simulation topples).
    early_stop: bool = False
    #: "At rest": linear speed below this many box sizes (the scene's smallest extent) per second
    #: and angular speed below ``rest_angular_rad_s``. What guards the answer is the growth test
    #: below, not these thresholds: a block that will still fall speeds up. ``default`` uses
    #: 0.4 / 0.4 (debris rocking after a collapse counts as settled unless it speeds up).
    rest_speed_sizes_per_s: float = 0.05
    rest_angular_rad_s: float = 0.05
    rest_duration_s: float = 0.2
    rest_min_time_s: float = 0.3
    #: "Not growing": no box may end the rest window more than this factor livelier than it
    #: began it. Resting contacts creep (a stacked block drifting at ~1 mm/s, 0.3% faster every
    #: 0.05 s, kept a plain two-block stack running to the horizon with a factor of 1), while a tower
    #: starting to tip speeds up several-fold in 0.2 s. Motion below
    #: ``physics.REST_NOISE_FLOOR_PER_S`` never counts as growing.
    rest_growth_factor: float = 1.1
    #: The step never exceeds this fraction of the boxes' time scale sqrt(size / g): small boxes
    #: get finer steps (3 mm cubes sank through each other at 1/240 s). 0.03 leaves 0.2 m blocks
    #: at 1/240 s and gives 3 mm cubes ~0.5 ms.
    max_step_fraction_of_time_scale: float = 0.03
    #: Collapse steps: once any box has clearly fallen (``collapse_drop_fraction``, after the push),
    #: the scene is collapsing. Falling blocks hitting each other are chaotic at any step size: only the
    #: statistics of the outcome matter, and they survive coarser steps, while the delicate part
    #: (does anything start to fall?) ran at the fine step. From then on the step is this integer
    #: multiple of the fine step, with ``collapse_solver_iterations``. 1 switches this off.
    collapse_step_factor: int = 1
    collapse_solver_iterations: int | None = None  # None: keep solver_iterations
    #: A collapse step is only as coarse as lets no box travel more than this fraction of the
    #: smallest box extent per step (chosen every 0.05 s from the fastest box): a 30-block tower's
    #: top blocks hit the floor at 11 m/s and would sink deep into it in one coarse step.
    collapse_max_travel_fraction: float = 0.5
    #: The collapse starts when a box's centre has dropped by this fraction of its smallest extent:
    #: far more than the fall query's 0.125, which a 30-block stack compressing under its own weight
    #: at coarse steps can reach without anything falling.
    collapse_drop_fraction: float = 0.5

    #: Settling: the first ``settle_s`` of a rollout run each step as ``settle_substeps`` finer
    #: steps. Contacts start cold (a box on the floor plane starts with one contact point, Bullet
    #: adds the rest over the next steps), and at coarse steps that start kicks resting blocks: at
    #: 1/180 s a delicately balanced tower, static at 1 ms steps, crept 2 cm in 2 s and toppled
    #: at 3 s. 1 switches this off.
    settle_s: float = 0.0
    settle_substeps: int = 1

    def __post_init__(self) -> None:
        _non_negative(self.settle_s, "settle_s")
        if isinstance(self.settle_substeps, bool) or not isinstance(self.settle_substeps, int) \
                or not 1 <= self.settle_substeps <= 100:
            raise ConfigError("settle_substeps",
                              f"must be an integer in [1, 100] (1: no settling substeps), got {self.settle_substeps!r}")
        _positive(self.time_step_s, "time_step_s")
        _positive(self.horizon_s, "horizon_s")
        _positive(self.solver_residual_threshold, "solver_residual_threshold")
        _positive(self.depenetration_tolerance_fraction, "depenetration_tolerance_fraction")
        if not 0 <= self.warm_start_factor <= 1:
            raise ConfigError("warm_start_factor", f"must be in [0, 1], got {self.warm_start_factor!r}")
        for name in ("rest_speed_sizes_per_s", "rest_angular_rad_s", "rest_duration_s"):
            _positive(getattr(self, name), name)
        _non_negative(self.rest_min_time_s, "rest_min_time_s")
        if not isinstance(self.rest_growth_factor, (int, float)) or not 1 <= self.rest_growth_factor < 10:
            raise ConfigError("rest_growth_factor", f"must be in [1, 10), got {self.rest_growth_factor!r}")
        _positive(self.max_step_fraction_of_time_scale, "max_step_fraction_of_time_scale")
        _positive(self.collapse_max_travel_fraction, "collapse_max_travel_fraction")
        _positive(self.collapse_drop_fraction, "collapse_drop_fraction")
        if self.time_step_s > self.horizon_s:
            raise ConfigError("time_step_s", "must not exceed horizon_s")
        if not isinstance(self.solver_iterations, int) or not 1 <= self.solver_iterations <= 10_000:
            raise ConfigError("solver_iterations", f"must be an integer in [1, 10000], got {self.solver_iterations!r}")
        if isinstance(self.collapse_step_factor, bool) or not isinstance(self.collapse_step_factor, int) \
                or not 1 <= self.collapse_step_factor <= 100:
            raise ConfigError("collapse_step_factor",
                              f"must be an integer in [1, 100] (1: no collapse steps), got {self.collapse_step_factor!r}")
        if self.collapse_solver_iterations is not None and (
                isinstance(self.collapse_solver_iterations, bool) or not isinstance(self.collapse_solver_iterations, int)
                or not 1 <= self.collapse_solver_iterations <= 10_000):
            raise ConfigError("collapse_solver_iterations",
                              f"must be an integer in [1, 10000] or None, got {self.collapse_solver_iterations!r}")

    @property
    def steps(self) -> int:
        return int(round(self.horizon_s / self.time_step_s))

    def time_step_for(self, scale_m: float, gravity_m_s2: float) -> float:
        """The step for a scene whose smallest box extent is ``scale_m`` (see the field above)."""
        return min(self.time_step_s, self.max_step_fraction_of_time_scale * math.sqrt(scale_m / gravity_m_s2))


PRESETS: dict[str, SimSettings] = {
    # The paper's settings: 1 ms steps for the full 2 s, a fully converged solver, no shortcuts.
    "paper": SimSettings(name="paper", time_step_s=0.001, horizon_s=2.0, solver_iterations=50),
    # 1 ms / 2 s with 20 solver iterations: close to `paper` (mean |dFF| ~0.006) at ~1.8x its speed.
    "accurate": SimSettings(name="accurate", time_step_s=0.001, horizon_s=2.0, solver_iterations=20),
    # 1/240 s steps throughout (1/233 s for 0.2 m blocks, by the size cap), boxes as plain rigid
    # bodies (maximal coordinates) with a full warm start, up to 100 solver iterations (to a residual
    # of 3e-6: a looser 1e-5 toppled a delicately balanced tower that stands), the first 0.1 s in
    # half steps (settling, see SimSettings), and rollouts that end once everything has been at rest
    # (and slowing down) for 0.2 s. The default until collapse steps.
    "fine": SimSettings(name="fine", time_step_s=1 / 240, horizon_s=2.0, solver_iterations=100,
                        solver_residual_threshold=3e-6, warm_start_factor=1.0, maximal_coordinates=True,
                        early_stop=True, settle_s=0.1, settle_substeps=2),
    # The default: `fine`'s solver at 1/180 s steps until something falls, then 4x coarser collapse
    # steps (the delicate question, does anything start to fall, gets the fine step; the chaotic
    # collapse only needs its statistics); the first 0.1 s in half steps (settling); a 0.15 s rest
    # window from 0.2 s on, "at rest" read as slower than 0.4 sizes/s and 0.4 rad/s and not
    # speeding up. See README for its speed and accuracy against `paper`
    # (benchmarks/accuracy_vs_time.py). Without settling the delicately balanced tower creeps (2 cm
    # in 2 s, toppling at 3 s); fewer solver iterations (85, 70) or coarser fine steps (1/160 s)
    # turn towers the authors' simulation keeps standing into falls; shorter rest windows or an
    # earlier collapse fail other hard cases (tests/test_hard_cases.py, tests/test_paper_data.py).
    "default": SimSettings(name="default", time_step_s=1 / 180, horizon_s=2.0, solver_iterations=100,
                           solver_residual_threshold=3e-6, warm_start_factor=1.0, maximal_coordinates=True,
                           early_stop=True, max_step_fraction_of_time_scale=0.04, collapse_step_factor=4,
                           rest_duration_s=0.15, rest_min_time_s=0.2,
                           rest_speed_sizes_per_s=0.4, rest_angular_rad_s=0.4, settle_s=0.1, settle_substeps=2),
}


def preset(name: str) -> SimSettings:
    try:
        return PRESETS[name]
    except KeyError:
        raise ConfigError("preset", f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}") from None


@dataclass(frozen=True)
class QuerySpec:
    """Which queries to compute and their thresholds.

    fall_threshold_fraction: an object has fallen when its centre's z dropped by more than this
        fraction of its own smallest extent. The default 0.125 is the paper's "0.025 unit" read in
        the stimulus files' units (0.025 m on 0.2 m blocks).
    bump_group: the group whose share of fallen-off objects the ``bump`` query reports (paper:
        red / (red + yellow)).
    """

    queries: frozenset[str] = frozenset({"fall"})
    fall_threshold_fraction: float = 0.125
    bump_group: str = "red"

    def __post_init__(self) -> None:
        unknown = sorted(set(self.queries) - set(ALL_QUERIES))
        if unknown:
            raise ConfigError("queries", f"unknown query {unknown[0]!r}; choose from {', '.join(ALL_QUERIES)}")
        if not self.queries:
            raise ConfigError("queries", f"ask for at least one of {', '.join(ALL_QUERIES)}")
        _positive(self.fall_threshold_fraction, "fall_threshold_fraction")

    def wants(self, name: str) -> bool:
        return name in self.queries


def parse_queries(text: str) -> frozenset[str]:
    """``"fall,direction"`` -> frozenset; raises ConfigError for unknown names."""
    names = frozenset(part.strip() for part in text.split(",") if part.strip())
    QuerySpec(queries=names)  # validates
    return names
