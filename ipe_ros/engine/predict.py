"""A prediction: the Monte Carlo IPE (paper Eq. S5) on one scene, aggregated.

Its samples and their self-check are one plan of the Monte Carlo loop (``montecarlo``), which runs
them through the injected ``map_fn(fn, items, on_lost=...)`` (``WorkerPool.map`` for worker
processes; None runs samples in this process): the sampler neither knows nor cares where samples
run. Each sample i gets the i-th child of ``SeedSequence(seed)``, so a prediction is a function of
(scene, settings, seed) alone. Here too: the up-front cost estimate that refuses what cannot fit a
budget, and ``predict_many`` for batch work.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from .config import DEFAULT_BUDGET_S, DEFAULT_MODEL, DEFAULT_PRESET, DEFAULT_QUERIES, ModelConfig, SimSettings, preset
from .errors import ConfigError, shown
from .sampling.estimate import Prediction, aggregate, sample_any_fall, sample_fall_fraction, wilson_interval
from .checking.fidelity import check_request as check_fidelity_request
from .checking.envelope import validated_for_all
from .checking.fidelity import (DEFAULT_CHECK, NO_CHECK, FidelityReport, SelfCheck, coverage_ahead, is_reference,
                       look_ahead_split, reference_settings, refine_in_task, verification_count)
from .sampling.montecarlo import (MapFn, MonteCarlo, Plan, check_budget, check_seed, check_some_sample_finished, child_seeds,
                         far_over_budget, together)
from .perceptions import perception_source
from .sampling.decide import Sequential
from .sampling.perturb import is_deterministic
from .results.outcome import rigid_reruns
from .sampling.rollout import SampleOutcome, SampleTask, lost, run_sample, take_refined
from .checking.self_check import checking
from .query import QUERIES, QuerySpec
from .scene.bodies import DEFAULT_MAX_OBJECTS, Scene
from .scene.mesh_repair import repaired_sources
from .scene.validation import validate_scene

@dataclass(frozen=True)
class AdaptiveStop:
    """Anytime sampling: draw samples in batches and stop early once a rule is met.

    ci_width: stop once the 95% interval of ``fall_fraction`` (or, when only ``any_fall`` is asked,
        of ``any_fall_probability``) is at most this wide, after at least ``min_samples`` good samples.
    deadline_s: stop before the next batch would end after this many seconds of sampling (the
        first batch always runs). Which samples are used depends on timing only through how many:
        sample i is always the i-th child seed, so n samples give the answer of a k = n run.
    batch_size: samples per batch; a multiple of the worker count keeps every worker busy.
    """

    ci_width: float | None = None
    deadline_s: float | None = None
    batch_size: int = 4
    min_samples: int = 4

    def __post_init__(self) -> None:
        if self.ci_width is not None and not (isinstance(self.ci_width, (int, float)) and 0 < self.ci_width <= 1):
            raise ConfigError("ci_width", f"must be in (0, 1], got {shown(self.ci_width)}")
        if self.deadline_s is not None and not (isinstance(self.deadline_s, (int, float)) and self.deadline_s > 0
                                                and math.isfinite(self.deadline_s)):
            raise ConfigError("deadline_s", f"must be a finite number of seconds > 0, got {shown(self.deadline_s)}")
        for name in ("batch_size", "min_samples"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(name, f"must be an integer >= 1, got {shown(value)}")


def make_tasks(scene: Scene, model: ModelConfig, settings: SimSettings, query: QuerySpec, seed: int,
               record_every: int = 0, record_samples: int | None = None) -> list[SampleTask]:
    """k tasks, one child seed each; the ground-truth model (sigma = phi = 0) needs only one.

    Trajectories (every ``record_every`` steps) are recorded for the first ``record_samples``
    samples only (None: all), since only the rollouts that rerun will show need them.
    """
    k = 1 if is_deterministic(scene, model) else model.samples
    seeds = child_seeds(seed, k)
    recorded = k if record_samples is None else record_samples
    return [SampleTask(scene=scene, model=model, settings=settings, query=query, index=i, seed=s,
                       record_every=record_every if i < recorded else 0) for i, s in enumerate(seeds)]


#: Wall seconds per pybullet step and dynamic body, for the up-front cost estimate (a 10-block
#: tower steps in ~150 us on this project's 2-core machine: benchmarks/time_budget.py). An
#: estimate, not a promise: the deadline enforces the budget.
SECONDS_PER_BODY_STEP = 15e-6

#: what one watched contact pair adds to a rollout: its start check and its part of the answer
#: (~27 us measured with 20,100 pairs of a 200-box scene; the per-step watch costs per contact)
SECONDS_PER_WATCHED_PAIR = 30e-6


@dataclass(frozen=True)
class RolloutCost:
    """The most work one rollout of a scene can take: it runs to the horizon without early stop."""

    steps: int
    bodies: int
    seconds: float
    pairs: int = 0


def rollout_cost(scene: Scene, model: ModelConfig, settings: SimSettings, pairs: int = 0) -> RolloutCost:
    """Steps x bodies of one sample (every phi value) at the step the scene gets, and ``pairs`` watched
    contact pairs, and its estimated time."""
    from .simulation.world import time_step_of

    dt = time_step_of(scene, settings)
    ticks = math.ceil(settings.horizon_for(scene.horizon_s) / dt)
    settle_ticks = math.ceil(settings.settling.duration_s / dt)
    steps = (ticks + settle_ticks * (settings.settling.substeps - 1)) * len(model.phi_m_s2)
    bodies = len(scene.dynamic_objects)
    # steps counts every phi value's run already; each run watches the pairs once more
    seconds = steps * bodies * SECONDS_PER_BODY_STEP + pairs * SECONDS_PER_WATCHED_PAIR * len(model.phi_m_s2)
    return RolloutCost(steps=steps, bodies=bodies, seconds=seconds, pairs=pairs)


def check_request(scene: Scene, query: QuerySpec, max_objects: int = DEFAULT_MAX_OBJECTS, *,
                  model: ModelConfig | None = None, settings: SimSettings | None = None,
                  budget_s: float | None = None) -> None:
    """Reject what cannot be answered before any simulation starts: a bad scene, a query it cannot
    answer, or (given a budget) a scene whose single rollout is estimated to take far longer than it
    (``montecarlo.far_over_budget``; nearer, the deadline cuts the samples off)."""
    validate_scene(scene, max_objects=max_objects)
    for name in sorted(query.queries):
        QUERIES[name].check(scene, query)
    if budget_s is not None and model is not None and settings is not None:
        cost = rollout_cost(scene, model, settings, len(query.contact_pairs) if "contact" in query.queries else 0)
        if far_over_budget(cost.seconds, budget_s):
            watched = f" and {cost.pairs} contact pairs" if cost.pairs else ""
            raise ConfigError("budget_s", f"one rollout of this scene takes up to {cost.steps} steps x {cost.bodies} "
                                          f"bodies{watched} (~{cost.seconds:.3g} s), far more than the budget of "
                                          f"{budget_s:g} s; raise the budget, shorten horizon_s, or simplify the "
                                          "scene" + (" or ask fewer pairs" if cost.pairs else ""))


def _from_perception(tasks: list[SampleTask], scene: Scene, model: ModelConfig, seed: int, map_fn: MapFn | None,
                     perceived, evidence, budget_s: float | None) -> tuple[list[SampleTask], object, float | None]:
    """With a perception that draws from a posterior (vision, depth, a registered one), each
    sample's scene is a state of it (and the model's sigma 0: the posterior is the noise); the
    tasks, the perceived scenes used, and the budget the chain left. The chain runs here unless
    ``perceived`` is given, on the samples' workers; one that needs evidence within its share of
    the budget (``evidence.Evidence.budget_share``)."""
    source = perception_source(model.perception)
    if not source.posterior:
        return tasks, perceived, budget_s
    if perceived is None:
        perceived, budget_s = source.perceive_within(scene, model, seed, map_fn, evidence, budget_s)
    if len(perceived.scenes) < len(tasks):
        raise ConfigError("samples", f"{len(perceived.scenes)} perceived scenes for {len(tasks)} samples")
    sampled = dataclasses.replace(model, sigma_m=0.0)
    return ([dataclasses.replace(t, scene=perceived.scenes[t.index], model=sampled) for t in tasks], perceived,
            budget_s)


def check_ci_width(ci_width: float | None, query: QuerySpec) -> None:
    """A target interval width needs an interval to watch: the fall or the any_fall query's."""
    if ci_width is not None and not (query.wants("fall") or query.wants("any_fall")):
        raise ConfigError("ci_width", "a target interval width needs the fall or any_fall query; add one to the "
                                      "queries or drop the target width")


@dataclass(frozen=True)
class Request:
    """What a prediction (``predict``) or a robot question (``actions.ask``) is asked: with ``model``,
    ``settings``, ``query`` and ``seed``, stopping by ``stop`` (None: all k samples; a prediction's
    ``AdaptiveStop``, a question's ``Sequential`` rule), within ``budget_s`` wall seconds (None: no
    budget), checked by ``check`` (None or ``SelfCheck(enabled=False)``: the fast physics alone).
    The defaults are the CLI's and the node's (``request.build_request`` makes one from their
    inputs, checked once)."""

    model: ModelConfig = DEFAULT_MODEL
    settings: SimSettings = preset(DEFAULT_PRESET)
    query: QuerySpec = QuerySpec(queries=DEFAULT_QUERIES)
    seed: int = 0
    stop: AdaptiveStop | Sequential | None = None
    budget_s: float | None = DEFAULT_BUDGET_S
    check: SelfCheck | None = DEFAULT_CHECK


@dataclass(frozen=True)
class Context:
    """What a prediction needs that is not the question: where its samples run (``map_fn``, e.g.
    ``WorkerPool.map``; None: in this process), what it records (trajectories every ``record_every``
    steps of the first ``record_samples`` samples, for rerun), the largest scene it takes
    (``max_objects``), and what its perception draws from: the ``evidence`` its chain is given, or
    the ``perceived`` scenes of a chain already run (the node's one posterior per view). A question
    also reports its progress to ``on_progress``; whatever that raises ends it (a cancellation)."""

    map_fn: MapFn | None = None
    record_every: int = 0
    record_samples: int | None = None
    max_objects: int = DEFAULT_MAX_OBJECTS
    perceived: Any = None
    evidence: Any = None
    on_progress: Callable[[dict], None] | None = None


def predict(scene: Scene, request: Request, context: Context | None = None) -> Prediction:
    """Run the IPE on one scene and aggregate (failed rollouts are counted in ``failed_samples``).

    ``context.record_every``/``record_samples``: record trajectories (for rerun) every N simulation steps
    for the first M samples; recording never changes the outcome. ``request.stop``: anytime sampling
    (a deadline or a target interval width); ``Prediction.stopped_by`` says which rule ended it.
    ``request.budget_s``: the most wall seconds the prediction may take. A scene whose one rollout cannot
    fit is refused (ConfigError naming budget_s); samples still running when it runs out are cut
    off and the answer uses the rest (``stopped_by: "budget"``). Which samples finish in time is
    the one thing here that depends on timing.

    A perception that draws from a posterior (``model.perception``: vision, depth, a registered
    one; ``engine.perceptions``): the k noisy scenes are states of it, from its chain run here (in a
    worker when ``context.map_fn`` is given, seeded from ``seed`` on a stream of its own; given
    ``context.evidence`` when the source needs it, within its share of ``budget_s``) or taken from
    ``context.perceived``.

    ``request.check``: how the answer checks its fast physics against the reference
    (``engine.checking.fidelity``): unhealthy rollouts refined, ``check.verify_samples`` samples
    verified in the same map as the fast ones, everything rerun at the reference on disagreement;
    ``Prediction.fidelity`` says what happened. None or ``SelfCheck(enabled=False)``: the fast
    physics alone.
    """
    context = context or Context()
    model, settings, query, seed = request.model, request.settings, request.query, request.seed
    stop, budget_s, check, map_fn = request.stop, request.budget_s, request.check, context.map_fn
    if stop is not None and not isinstance(stop, AdaptiveStop):
        raise ConfigError("stop", "a prediction stops by an AdaptiveStop (a deadline or an interval width); a "
                                  "Sequential rule decides robot questions")
    check_seed(seed)
    check_budget(budget_s)
    check_fidelity_request(check)
    check_request(scene, query, context.max_objects, model=model, settings=settings, budget_s=budget_s)
    check_ci_width(None if stop is None else stop.ci_width, query)
    tasks = make_tasks(scene, model, settings, query, seed, context.record_every, context.record_samples)
    tasks, perceived, budget_s = _from_perception(tasks, scene, model, seed, map_fn, context.perceived,
                                                  context.evidence, budget_s)
    check = NO_CHECK if check is None or is_reference(settings) else check
    validated = _validated(tasks, model, settings, check, stop)
    if validated:  # nothing verified or covered: only unhealthy rollouts are rerun
        check = dataclasses.replace(check, verify_samples=0, cover_samples=0)
    loop = MonteCarlo(run_sample, lost, map_fn, budget_s)  # the budget counts from here
    anytime = None if is_deterministic(scene, model) else stop
    outcomes, stopped_by, report = loop.drive(_prediction(tasks, query, settings, check, anytime, budget_s,
                                                          loop.elapsed_s, validated))
    return _aggregate(scene, model, settings, query, seed, tasks, outcomes, loop.elapsed_s(), stopped_by, stop=stop,
                      budget_s=budget_s, perceived=perceived, fidelity=report)


def _validated(tasks: list[SampleTask], model: ModelConfig, settings: SimSettings, check: SelfCheck,
               stop: AdaptiveStop | None) -> str:
    """Why the answer needs no verification (``checking.envelope``), or "": every scene the samples
    start from (a posterior's samples each their own: one drawn tilted onto an edge is not a box
    lying on a face) inside the validated envelope, at a fixed k (anytime sampling may stop after a
    few samples)."""
    if not check.enabled or check.always_verify or stop is not None:
        return ""
    return validated_for_all((t.scene for t in tasks), model, settings)


def _prediction(tasks: list[SampleTask], query: QuerySpec, settings: SimSettings, check: SelfCheck,
                stop: AdaptiveStop | None, budget_s: float | None, clock: Callable[[], float],
                validated: str = "") -> Plan:
    """A prediction's samples, then their self-check, as a plan (``montecarlo``): returns the
    outcomes the answer uses, what stopped the sampling, and the check's report.

    The verification samples are rerun at the reference in the first round, beside the fast samples;
    with a fixed k (``stop`` None) the coverage sample runs beside the last quarter of them
    (``fidelity.look_ahead_split``), picked from the rest. ``validated``: why the scene needs no
    verification (``check`` then verifies and covers nothing), for the check's verdict."""
    reference = reference_settings(settings.horizon_s)
    verified: dict[int, SampleOutcome] = {}
    refined: dict[int, SampleOutcome] = {}  # unhealthy samples' reruns at the reference, made in their own task
    refine = refine_in_task(check, settings)
    if refine is not None:
        tasks = [dataclasses.replace(t, refine=refine) for t in tasks]
    first = list(range(verification_count(check, len(tasks))))
    stopped_by = "samples"
    if stop is None:
        split = look_ahead_split(check, len(tasks))
        outcomes = yield from _beside(tasks, first, tasks[:split], reference, verified, refined)
        if split < len(tasks):
            ahead = coverage_ahead(outcomes, verified, check, len(tasks))
            verified.update({i: refined[i] for i in ahead if i in refined})  # rerun already
            outcomes += yield from _beside(tasks, [i for i in ahead if i not in refined], tasks[split:], reference,
                                           verified, refined)
    else:
        per_sample_answer = sample_fall_fraction if query.wants("fall") else sample_any_fall
        outcomes = []
        for at in range(0, len(tasks), stop.batch_size):
            batch_started = clock()
            outcomes += yield from _beside(tasks, first if at == 0 else [], tasks[at:at + stop.batch_size],
                                           reference, verified, refined)
            if len(outcomes) == len(tasks):
                break
            stopped_by = _anytime_stop(stop, outcomes, per_sample_answer, clock(), batch_started)
            if stopped_by != "samples":
                break
    check_some_sample_finished(outcomes, budget_s)
    if is_reference(settings):
        return outcomes, stopped_by, FidelityReport("reference", settings=(("samples", settings.name),),
                                                    rigid_reruns=rigid_reruns(outcomes))
    outcomes, report = yield from checking(tasks[:len(outcomes)], outcomes, verified, check, reference, settings.name,
                                           validated, refined)
    return outcomes, stopped_by, report


def _beside(tasks: list[SampleTask], samples: list[int], batch: list[SampleTask], reference: SimSettings,
            verified: dict[int, SampleOutcome], refined: dict[int, SampleOutcome]) -> Plan:
    """One round: ``batch``, with ``samples`` rerun at the reference first (the longest tasks start
    first; their reruns go to ``verified``; these samples' fast runs are not refined, their rerun
    being at hand); returns the batch's outcomes, the reruns of those that ended unhealthy (made
    in their own task: ``Refine``) moved to ``refined``."""
    batch = [dataclasses.replace(t, refine=None) if t.index in samples else t for t in batch]
    both = yield [tasks[i].at(reference) for i in samples] + batch
    verified.update(zip(samples, both[:len(samples)]))
    outcomes, reruns = take_refined([t.index for t in batch], both[len(samples):])
    refined.update(reruns)
    return outcomes


def _anytime_stop(stop: AdaptiveStop, outcomes: list[SampleOutcome], per_sample_answer, now_s: float,
                  batch_started_s: float) -> str:
    """Anytime sampling after a batch: "deadline" when the next batch would end after it, "ci_width"
    when the answer's interval is narrow enough, else "samples" (go on)."""
    if stop.deadline_s is not None and now_s + (now_s - batch_started_s) > stop.deadline_s:
        return "deadline"
    ok = [o for o in outcomes if o.ok]
    if stop.ci_width is not None and len(ok) >= stop.min_samples:
        fall = float(np.mean([per_sample_answer(o) for o in ok]))
        lo, hi = wilson_interval(fall, len(ok))
        if hi - lo <= stop.ci_width:
            return "ci_width"
    return "samples"


def _aggregate(scene: Scene, model: ModelConfig, settings: SimSettings, query: QuerySpec, seed: int,
               tasks: list[SampleTask], outcomes: list[SampleOutcome], wall_s: float, stopped_by: str, *,
               stop: AdaptiveStop | None = None, budget_s: float | None = None, perceived=None,
               fidelity: FidelityReport | None = None) -> Prediction:
    request = {
        "sigma_m": model.sigma_m, "phi_m_s2": list(model.phi_m_s2),
        "force_direction_rad": model.force_direction_rad, "mu": model.mu, "preset": settings.name,
        "time_step_s": settings.time_step_s, "horizon_s": settings.horizon_for(scene.horizon_s),  # what ran
        "solver_iterations": settings.solver.iterations, "seed": seed, "queries": sorted(query.queries),
    }
    if not model.object_noise:  # the ground truth: no body's own noise drawn either
        request.update(object_noise=False)
    if query.contact_pairs:
        request.update(contact=[f"{a}:{b}" for a, b in query.contact_pairs])
    if stop is not None:
        request.update(ci_width=stop.ci_width, deadline_s=stop.deadline_s)
    if budget_s is not None:
        request.update(budget_s=budget_s)
    if perception_source(model.perception).posterior:
        request.update(perception=perceived.to_dict())
    repaired = {name: source.repaired for name, source in repaired_sources(scene).items()}
    if repaired:  # open meshes the engine was given closed: how (mesh_repair.closed_solid)
        request.update(repaired_meshes=repaired)
    prediction = aggregate(scene, outcomes, query=query,
                           deterministic=is_deterministic(scene, model), samples_requested=len(tasks),
                           wall_s=wall_s, request=request)
    if fidelity is not None:
        prediction = dataclasses.replace(prediction, fidelity=fidelity.verdict, refined_samples=fidelity.refined_samples,
                                         self_check=fidelity.to_dict())
    if perceived is not None:
        prediction = dataclasses.replace(prediction, perceived=perceived)
    if prediction.stopped_by == "budget":
        return prediction
    return dataclasses.replace(prediction, stopped_by=stopped_by)


def predict_many(requests: Sequence[tuple[Scene, ModelConfig, int]], settings: SimSettings, query: QuerySpec,
                 map_fn: MapFn | None = None, max_objects: int = DEFAULT_MAX_OBJECTS) -> list[Prediction]:
    """``[predict(scene, Request(model, settings, query, seed), Context(map_fn)) for scene, model, seed in requests]``,
    with every sample of every request in one ``map_fn`` call: equal answers (each request keeps its
    own seeds), but no worker waits for a prediction's last sample before the next one starts, and a
    cluster's round trip is paid once instead of per prediction. For batch work (the paper's
    analyses); ``wall_s`` of each answer is the whole map's time shared out by its samples.
    Requests whose perception draws from a posterior run one by one (each needs its chain first;
    depth perception, whose images only the caller has, is refused). Batch answers are
    not self-checked (``fidelity: "unverified"``): the paper's analyses reproduce fixed settings,
    and the check's extra samples would change what a resumable run stores.
    """
    requests = list(requests)
    answers: list[Prediction | None] = [None] * len(requests)
    batched: list[tuple[int, list[SampleTask]]] = []
    for i, (scene, model, seed) in enumerate(requests):
        if perception_source(model.perception).posterior:  # its chain first, then its samples
            answers[i] = predict(scene, Request(model=model, settings=settings, query=query, seed=seed, budget_s=None,
                                                check=None), Context(map_fn=map_fn, max_objects=max_objects))
            continue
        check_seed(seed)
        check_request(scene, query, max_objects)
        tasks = make_tasks(scene, model, settings, query, seed)
        batched.append((i, tasks))
    everything = sum(len(tasks) for _, tasks in batched)
    loop = MonteCarlo(run_sample, lost, map_fn)
    results = loop.drive(together([_prediction(tasks, query, settings, NO_CHECK, None, None, loop.elapsed_s)
                                   for _, tasks in batched]))
    wall_s = loop.elapsed_s()
    for (i, tasks), (outcomes, stopped_by, report) in zip(batched, results):
        scene, model, seed = requests[i]
        answers[i] = _aggregate(scene, model, settings, query, seed, tasks, outcomes,
                                wall_s * len(tasks) / max(1, everything), stopped_by, fidelity=report)
    return answers  # type: ignore[return-value]
