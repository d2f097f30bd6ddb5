"""The simulation settings' groups, one per concern of the stepper (engine/simulation/): the solver,
depenetration, settling, the collapse phase and early stopping. ``config.SimSettings`` holds one of
each; config.py re-exports them (``from .config import SolverSettings`` as before).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from .checks import boolean, integer, non_negative, positive
from .errors import ConfigError, shown


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


@dataclass(frozen=True)
class SolverSettings:
    """pybullet's constraint solver.

    iterations: solver iterations per step (the most; it stops earlier at the residual).
    residual_threshold: pybullet stops iterating once the residual is below this (scaled by scene
        size and step, see ``simulation.world.residual_threshold``). `default`'s 1e-5 keeps the
        delicately balanced tower within 0.3 mm over 2 s; at 1.5e-5 it topples
        (tests/test_hard_cases.py). Its collapse steps keep 3e-6 (``CollapseSettings``).
    warm_start_factor: warm start of the solver from the last step's impulses (pybullet's default
        0.85); 1.0 carries resting contacts over fully, which keeps stacks quiet at coarse steps.
    maximal_coordinates: boxes as plain rigid bodies (pybullet's ``useMaximalCoordinates``) instead
        of one-link multibodies: the classic sequential-impulse solver, cheaper per contact (thin boxes
        on the direct solver excepted: ``multibodies_from_aspect``).
    direct_solver_for_restitution: see the field.
    iterations_per_mass_ratio: the iterative solver passes impulses from body to body, and needs
        about as many iterations as the heaviest body outweighs the lightest: a 1000:1 heavy box on a
        light one drove it into the floor at 100 iterations and stands at 1000. So a scene gets at
        least this many iterations per unit of its mass ratio (up to ``max_iterations``); the residual
        threshold ends the iterations as soon as the contacts are solved, so easy steps cost nothing more.
    """

    iterations: int
    residual_threshold: float = 1e-7
    warm_start_factor: float = 0.85
    maximal_coordinates: bool = False
    iterations_per_mass_ratio: float = 1.0
    max_iterations: int = 2000
    #: Bounces need every contact of an impact solved at once. The sequential-impulse solver gives
    #: each contact its restitution in turn, and where a thrown ball wedged under a heavier body
    #: (against the floor) that added more energy than the ball brought (+150%). So a scene in which
    #: two touching surfaces can both bounce (Bullet multiplies restitutions) is solved by pybullet's
    #: direct MLCP solver (Dantzig), about 1.6x slower, up to a mass ratio of
    #: ``direct_solver_max_mass_ratio``: its pivoting loses precision as masses spread (a 450:1 stack
    #: of bouncy bodies gained 40% of its energy with it, none with sequential impulses). Scenes
    #: without restitution (the paper's towers) keep the sequential-impulse solver. The direct solver
    #: pushes resting bodies out of each other poorly (a 183 kg hull under an 861 kg one chattered 6% of
    #: its size deep in the floor at the horizon), so a rollout's last ``collapse.fine_before_end_s``
    #: runs on the sequential-impulse solver again, and a rollout at rest before the horizon runs
    #: that end phase before it ends: what rests at the end is pushed out.
    direct_solver_for_restitution: bool = True
    direct_solver_max_mass_ratio: float = 100.0
    #: The direct solver's friction is a box along the world's axes, not a cone: a box slid at 30 deg
    #: veered to 18 deg, one slid at 45 deg stopped at 0.71x Coulomb's distance. So where it is used
    #: (the fields around this one), it solves only the steps in which a contact whose surfaces can
    #: bounce closes faster than Bullet's restitution threshold, and the sequential-impulse solver,
    #: whose friction is a cone, every other step (simulation/impacts.py; docs/model.md). False: the
    #: direct solver for the whole rollout, as before (for comparison only).
    direct_solver_for_impacts_only: bool = field(default=False, metadata={"keyed": "when set"})
    #: Where a bounce is possible at all, the direct solver only where two surfaces that may touch
    #: combine to at least this restitution (Bullet multiplies the two; 0: any bounce), or a body is
    #: thrown in (``direct_solver_from_speed_m_s``). A bounce gives back e^2 of an impact's normal
    #: energy, under 1% below 0.1 (the health check's share of the scene's scale), and the direct
    #: solver's cost grows with the contacts it solves at once: a chain of 18 dominoes at 0.005 (0.05 on
    #: a 0.1 floor) took 2.7x the time of the sequential-impulse solver on the zoo, with the same answers.
    #: Thin boxes keep it at any restitution (``multibodies_from_aspect``: it is what holds their friction).
    direct_solver_min_restitution: float = field(default=0.0, metadata={"keyed": "when set"})
    #: A body that starts at least this fast (linear speed + spin x half diagonal) keeps the direct
    #: solver where a bounce is possible (``direct_solver_min_restitution``): it strikes
    #: the others in its first steps, and the sequential-impulse solver at `default`'s steps does not
    #: converge a fast impact into a stack, whatever the restitution (zoo launch 2027/1-2, balls at 3.8
    #: and 7.2 m/s: one object off in 2 of 16 samples; caps 2027/3, thrown at 8.6 m/s: 0.875 off, 0.44 on
    #: the direct solver). A domino nudged at 0.2-0.6 m/s tips; it does not strike. None: never.
    direct_solver_from_speed_m_s: float | None = field(default=None, metadata={"keyed": "when set"})
    #: Plain rigid bodies let friction creep. On the zoo's thin plates a tipped plate slid 5-8 mm, past
    #: its fall threshold (an eighth of its 14 mm thickness), in 88-100% of `default`'s samples; Bullet's
    #: multibodies solved by the direct solver hold it in about half, as `paper` and a third engine with
    #: hard friction do (MuJoCo's noslip; benchmarks/results/zoo_trials). So where the direct solver
    #: runs and a box is at least this many times as long as it is thin, the scene is built in
    #: multibodies whatever ``maximal_coordinates`` says. Only there: elsewhere multibodies answered
    #: the zoo alike at 1.1-1.4x the time (dominoes' 5-8:1 slabs included), and on the sequential-impulse
    #: solver they do not hold friction either. None: never.
    multibodies_from_aspect: float | None = field(default=None, metadata={"keyed": "when set"})
    #: Where the direct solver solves impacts, a body that can bounce has its contacts solved from
    #: when they touch, not from when they are found ahead. Bullet solves a contact found ahead (gap
    #: d > 0) to the normal speed e v - d / dt, restitution included: a ball a step away is slowed
    #: before it lands, the next step takes e of the slower speed, and a 2 m/s landing at 1 ms gave
    #: back none of its height (`paper`; tests/test_mechanics.py). Solved from the touch (pybullet's
    #: contactProcessingThreshold 0 for that body) it lands at its speed and gives back e of it. The
    #: travel limit, not contacts found ahead, keeps it from passing through what it meets; the
    #: impact's step removes no overlap by velocity (``use_direct_solver``), and the steps after it
    #: push out what is left. Its contact shows (simulation/impacts.py) once it touches: the step
    #: that solves it takes the direct solver.
    bounce_from_touch: bool = field(default=False, metadata={"keyed": "when set"})

    def __post_init__(self) -> None:
        integer(self.iterations, "solver.iterations", 1, 10_000)
        boolean(self.direct_solver_for_impacts_only, "solver.direct_solver_for_impacts_only")
        boolean(self.bounce_from_touch, "solver.bounce_from_touch")
        non_negative(self.iterations_per_mass_ratio, "solver.iterations_per_mass_ratio")
        integer(self.max_iterations, "solver.max_iterations", 1, 100_000)

        positive(self.residual_threshold, "solver.residual_threshold")
        least = self.direct_solver_min_restitution
        if not (_is_number(least) and 0 <= least <= 1):
            raise ConfigError("solver.direct_solver_min_restitution",
                              f"must be a restitution in [0, 1], got {shown(least)}")
        fast = self.direct_solver_from_speed_m_s
        if fast is not None and not (_is_number(fast) and math.isfinite(fast) and fast >= 0):
            raise ConfigError("solver.direct_solver_from_speed_m_s", f"must be a speed >= 0 or None, got {shown(fast)}")
        aspect = self.multibodies_from_aspect
        if aspect is not None and not (_is_number(aspect) and math.isfinite(aspect) and aspect >= 1):
            raise ConfigError("solver.multibodies_from_aspect",
                              f"must be a length-to-thickness ratio >= 1 or None, got {shown(aspect)}")
        if not 0 <= self.warm_start_factor <= 1:
            raise ConfigError("solver.warm_start_factor", f"must be in [0, 1], got {shown(self.warm_start_factor)}")


@dataclass(frozen=True)
class DepenetrationSettings:
    """Removing the overlaps that position noise creates (paper: "remove interpenetrations").

    tolerance_fraction: stop once no pair of boxes overlaps by more than this fraction of the
        smallest box extent.
    max_iterations: rounds before giving up with a PhysicsError.
    """

    tolerance_fraction: float = 1e-3
    max_iterations: int = 200

    def __post_init__(self) -> None:
        positive(self.tolerance_fraction, "depenetration.tolerance_fraction")
        integer(self.max_iterations, "depenetration.max_iterations", 1, 100_000)


@dataclass(frozen=True)
class SettlingSettings:
    """The first ``duration_s`` of a rollout run each step as ``substeps`` finer steps.

    Contacts start cold: a box on the floor plane starts with one contact point and Bullet adds the
    rest over the next steps. At coarse steps that start kicks resting blocks, enough to topple a
    delicately balanced tower that stands at 1 ms steps. ``substeps`` = 1 switches this off.
    """

    duration_s: float = 0.0
    substeps: int = 1

    def __post_init__(self) -> None:
        non_negative(self.duration_s, "settling.duration_s")
        integer(self.substeps, "settling.substeps", 1, 100, " (1: no settling substeps)")


@dataclass(frozen=True)
class CollapseSettings:
    """Coarser steps once the scene is collapsing.

    Once any box has clearly fallen (its centre dropped by ``drop_fraction`` of its smallest extent,
    after the push), falling blocks hitting each other are chaotic at any step size: only the
    statistics of the outcome matter, and they survive coarser steps, while the delicate part (does
    anything start to fall?) ran at the fine step. From then on the step is up to ``step_factor``
    times the fine step, with ``solver_iterations`` (None: keep the solver's), but never coarser
    than the travel limit allows (``SimSettings.max_travel_fraction``), nor while a body is deeper
    inside another than ``EarlyStopSettings.max_penetration_fraction`` (the solver pushes it out by
    a share of the depth per step, so coarse steps leave it there), nor in the last
    ``fine_before_end_s`` of the horizon, so that a rollout ends on fine steps with what landed late
    pushed out again. ``drop_fraction`` is far above
    the fall query's 0.125, which a 30-block stack compressing under its own weight can reach
    without anything falling. ``step_factor`` = 1 switches this off.

    ``end_substeps``: those last ``fine_before_end_s`` run in at least this many substeps per tick. A
    collapse still under way at the horizon is read mid-impact: at 1/180 s steps 49 of 576 tower
    rollouts run to 2 s (asked where things land) end with a body > 5% inside another, each then
    rerun at the reference by the self-check (9.8 reference samples per k = 48 tower prediction); at
    half steps for the last 0.1 s, 2 (2.75 with the check's coverage; benchmarks/HISTORY.md, "the
    self-check's policies"). Since ``end_travel_fraction`` gives a fast end the substeps it needs,
    ``default`` uses 1: half steps for slow ends too changed no fall on the towers and cost them 1-3%.

    ``end_travel_fraction``: in those last ``fine_before_end_s``, also as many substeps as keep the
    fastest corner within this fraction of the smallest extent per substep (None: ``end_substeps``
    alone), checked at every read. A body caught mid-impact at the horizon ends inside what it hit by
    about its last substep's travel, which the solver has not yet pushed out, so the fraction is the
    self-check's bar for a healthy end (5%): half steps left the 10-block depth example's one
    unhealthy rollout 10.9% inside another (a tower landing at 5 m/s), rerun at the reference for
    0.4 s of a worker; three substeps end it healthy. Rollouts whose bodies end slower than about
    0.1 sizes per fine step keep ``end_substeps`` and are unchanged.

    ``max_created_energy_fraction``: collapse steps are on trial. When, at a look after they began
    (and before the end phase), the scene holds more energy than the least it held so far by more
    than this fraction of its energy scale (``health.energy_scale_j``), the rollout goes back to the
    look where they began and runs on without them, as a preset without collapse steps would (to
    within pybullet's restore of a saved state, ~1e-6 m). After the push nothing does work on the
    scene, so its energy can only fall: a rise is the solver's. A stack landing as one body is where
    it happens: at a coarse step the solver's iterations cannot carry the impact down the stack, and
    pushing the cubes out of each other launched the top of a 39-cube column 0.9 m up (20-30 J, half
    the scene's energy scale) and knocked the cubes below over, which `paper` leaves standing
    (tests/test_hard_cases.py, benchmarks/HISTORY.md). ``RolloutResult.collapse_undone`` says where.
    1%, the bar the self-check holds a rollout's energy gain to: 31 of 2880 rollouts of the authors'
    60 towers (k = 48) make 1-3.3% and are undone; the landing column makes 47-52%.

    ``anchor_after_steps``: a trial that has taken this many pybullet steps without making a tenth of
    that energy begins again at its next look (None: one trial from the collapse's start), so that an
    undo reruns at the fine step only what follows the latest anchor. A domino chain's last impacts
    made energy at 1.3-1.9 s and sent half its rollouts back to 0.3 s, to run the rest at the fine
    step (the zoo's dominoes 1.1-1.15x faster with anchors, its longest chains up to 1.4x, the same
    answers). pybullet's saveState costs 5-20
    steps' time, hence rare anchors: 300 steps cost the towers nothing measurable (a tower's collapse
    takes about 140). Saving the world changes nothing in it: a rollout whose collapse steps make no
    energy is bit for bit the same.

    ``quiet_sizes_per_s``: a collapse is over once no body's corner moves faster than this many
    smallest extents per second while some body has not clearly fallen: fine steps and the full
    solver again, and a new collapse once something clearly falls from where it is then. What still
    stands after a fall is as delicate as before it: a cube landing on a column of eight left it
    still, then rocked it at collapse steps, ever more without making energy, until it fell in 1-3
    of 8 samples (`paper`: 0); 0.5 still let a column of seven fall. A fall that ends still before
    the look that would start the collapse takes no collapse steps at all. Where everything has
    fallen nothing is delicate, and the collapse steps go on.

    Measured on the zoo (benchmarks/collapse_trial.py: 6 scenes per family, k = 16, against `paper`,
    unchecked): the undo at 1% takes ramp's mean / worst |dP| from 0.086 / 0.875 to 0.016 / 0.188
    and drop's from 0.016 / 0.188 to 0 (at 5%: ramp 0.070 / 0.562), at 15-60% more time on ramps,
    drops and domino chains (no domino answer changed); the end at quiet changes no zoo answer and
    costs plates 15%.

    ``residual_threshold``: the collapse steps' own solver residual threshold (None: the solver's),
    scaled as the solver's is (``simulation.world.residual_threshold``). A landing deep in a small
    box needs its push-out solved as tightly as before: with the fine steps' 1e-5, `default` knocked
    the zoo's stacks 2026/0 small box out in 25% of 32 samples where the fine steps did in 9% (the
    hard case below); at 3e-6, 16%.

    ``max_travel_fraction``: the collapse steps' own travel limit (None: the preset's
    ``SimSettings.max_travel_fraction``). A falling body that travels half the smallest extent in
    one coarse step lands deep in what it hits, and the solver's push-out throws small bodies
    aside: on the zoo's ``stacks`` 2026/0 (a 3 cm box under larger, heavier ones) `default` knocked
    the small box out in 31-44% of the samples at 0.5, 16-19% at 0.25, `paper` 9-16%, `default`
    without collapse steps 13-16% (benchmarks/results/zoo_stacks/mass_ratio.md).
    """

    step_factor: int = 1
    solver_iterations: int | None = None
    drop_fraction: float = 0.5
    fine_before_end_s: float = 0.1
    end_substeps: int = 1
    max_created_energy_fraction: float = 0.01
    quiet_sizes_per_s: float = 1.0
    #: part of a stored result's key only when set: results stored before it keep their keys
    max_travel_fraction: float | None = field(default=None, metadata={"keyed": "when set"})
    end_travel_fraction: float | None = field(default=None, metadata={"keyed": "when set"})
    anchor_after_steps: int | None = field(default=None, metadata={"keyed": "when set"})
    residual_threshold: float | None = field(default=None, metadata={"keyed": "when set"})

    def __post_init__(self) -> None:
        integer(self.step_factor, "collapse.step_factor", 1, 100, " (1: no collapse steps)")
        if self.residual_threshold is not None:
            positive(self.residual_threshold, "collapse.residual_threshold")
        if self.max_travel_fraction is not None:
            positive(self.max_travel_fraction, "collapse.max_travel_fraction")
        if self.end_travel_fraction is not None:
            positive(self.end_travel_fraction, "collapse.end_travel_fraction")
        if self.anchor_after_steps is not None:
            integer(self.anchor_after_steps, "collapse.anchor_after_steps", 1, 1_000_000, " or None")
        if self.solver_iterations is not None:
            integer(self.solver_iterations, "collapse.solver_iterations", 1, 10_000, " or None")
        positive(self.drop_fraction, "collapse.drop_fraction")
        non_negative(self.fine_before_end_s, "collapse.fine_before_end_s")
        integer(self.end_substeps, "collapse.end_substeps", 1, 16)
        positive(self.max_created_energy_fraction, "collapse.max_created_energy_fraction")
        positive(self.quiet_sizes_per_s, "collapse.quiet_sizes_per_s")

    @property
    def enabled(self) -> bool:
        return self.step_factor > 1


@dataclass(frozen=True)
class EarlyStopSettings:
    """Ending a rollout once nothing can change any more (the task's business, not the physics').

    A rollout ends once every dynamic box has been at rest for ``duration_s`` (after the push and
    ``min_time_s``). "At rest": slower than ``speed_sizes_per_s`` box sizes (the scene's smallest
    extent) per second and ``angular_rad_s``, and not speeding up: no box may end the window more
    than ``growth_factor`` livelier than it began it. What guards the answer is that growth test,
    not the thresholds: a block that will still fall speeds up (a tower starting to tip is slow but
    accelerating), while resting contacts creep slowly at a near-constant rate. When only ``fall``
    is asked, a box that has fallen (or cannot fall) counts as settled. Nor has a scene come to rest
    while a body is still deeper than ``max_penetration_fraction`` of its smallest extent inside
    another: the solver is still pushing it out (after a collapse at coarse steps it can be 10%), so
    the rollout goes on at the fine step until it is out.
    """

    enabled: bool = False
    speed_sizes_per_s: float = 0.05
    angular_rad_s: float = 0.05
    duration_s: float = 0.2
    min_time_s: float = 0.3
    growth_factor: float = 1.1
    max_penetration_fraction: float = 0.05

    def __post_init__(self) -> None:
        positive(self.max_penetration_fraction, "early_stop.max_penetration_fraction")
        boolean(self.enabled, "early_stop.enabled")
        for name in ("speed_sizes_per_s", "angular_rad_s", "duration_s"):
            positive(getattr(self, name), f"early_stop.{name}")
        non_negative(self.min_time_s, "early_stop.min_time_s")
        if not isinstance(self.growth_factor, (int, float)) or not 1 <= self.growth_factor < 10:
            raise ConfigError("early_stop.growth_factor", f"must be in [1, 10), got {shown(self.growth_factor)}")
