"""The Monte Carlo IPE (paper Eq. S5): one seed per sample, an injected map, aggregation.

Parallelism is an injected ``map_fn(fn, items, on_lost=...)`` (``WorkerPool.map`` for worker
processes; None runs samples in this process): the sampler neither knows nor cares where samples
run. ``on_lost(item, reason)`` answers for an item whose worker died twice. Each sample i gets the i-th child of
``SeedSequence(seed)``, so a prediction is a function of (scene, settings, seed) alone.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Callable, Generator, Sequence

import numpy as np

from .config import ModelConfig, SimSettings
from .errors import ConfigError, shown
from .estimate import Prediction, aggregate, sample_any_fall, sample_fall_fraction, wilson_interval
from .fidelity import check_request as check_fidelity_request
from .fidelity import (DEFAULT_CHECK, NO_CHECK, FidelityReport, SelfCheck, confirmation_samples, contradicts,
                       coverage_ahead, coverage_samples, difference, is_reference, look_ahead_split, merge,
                       outcome_flags, reference_settings, scale_of, suspect, unhealthy, verification_count)
from .perceptions import perception_source
from .perturb import is_deterministic
from .rollout import SampleOutcome, SampleTask, failed, run_sample
from .query import QUERIES, QuerySpec
from .scene import DEFAULT_MAX_OBJECTS, Scene, validate_scene

MapFn = Callable[..., list]


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


def _check_seed(seed) -> None:
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError("seed", f"must be an integer >= 0, got {shown(seed)}")


def _run_tasks(tasks: list[SampleTask], map_fn: MapFn | None) -> list[SampleOutcome]:
    """The samples' outcomes, in order: through ``map_fn``, or in this process without one."""
    if map_fn is None:
        return [run_sample(t) for t in tasks]
    return map_fn(run_sample, tasks, on_lost=_lost)


def _lost(task: SampleTask, reason: str) -> SampleOutcome:
    return failed(task, f"WorkerLost: {reason}", worker_lost=True)


def make_tasks(scene: Scene, model: ModelConfig, settings: SimSettings, query: QuerySpec, seed: int,
               record_every: int = 0, record_samples: int | None = None) -> list[SampleTask]:
    """k tasks, one child seed each; the ground-truth model (sigma = phi = 0) needs only one.

    Trajectories (every ``record_every`` steps) are recorded for the first ``record_samples``
    samples only (None: all), since only the rollouts that rerun will show need them.
    """
    k = 1 if is_deterministic(scene, model) else model.samples
    seeds = np.random.SeedSequence(seed).spawn(k)
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
    from .simulation.world import fastest_initial_speed_m_s

    g = math.sqrt(sum(v * v for v in scene.gravity_m_s2))
    scale = min(b.smallest_extent_m for b in scene.dynamic_objects)
    dt = settings.time_step_for(scale, g, fastest_initial_speed_m_s(scene))
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
    answer, or (given a budget) a scene whose single rollout is estimated to take longer than it."""
    validate_scene(scene, max_objects=max_objects)
    for name in sorted(query.queries):
        QUERIES[name].check(scene, query)
    if budget_s is not None and model is not None and settings is not None:
        cost = rollout_cost(scene, model, settings, len(query.contact_pairs) if "contact" in query.queries else 0)
        if cost.seconds > budget_s:
            watched = f" and {cost.pairs} contact pairs" if cost.pairs else ""
            raise ConfigError("budget_s", f"one rollout of this scene takes up to {cost.steps} steps x {cost.bodies} "
                                          f"bodies{watched} (~{cost.seconds:.3g} s), more than the budget of "
                                          f"{budget_s:g} s; raise the budget, shorten horizon_s, or simplify the "
                                          "scene" + (" or ask fewer pairs" if cost.pairs else ""))


def _from_perception(tasks: list[SampleTask], scene: Scene, model: ModelConfig, seed: int, map_fn: MapFn | None,
                     perceived) -> tuple[list[SampleTask], object]:
    """With a perception that draws from a posterior (vision, depth), each sample's scene is a state
    of it (and the model's sigma 0: the posterior is the noise); the tasks and the perceived scenes used."""
    source = perception_source(model.perception)
    if not source.posterior:
        return tasks, perceived
    perceived = perceived or source.perceive(scene, model, seed, map_fn)
    if len(perceived.scenes) < len(tasks):
        raise ConfigError("samples", f"{len(perceived.scenes)} perceived scenes for {len(tasks)} samples")
    sampled = dataclasses.replace(model, sigma_m=0.0)
    return [dataclasses.replace(t, scene=perceived.scenes[t.index], model=sampled) for t in tasks], perceived


def _anytime(tasks: list[SampleTask], stop: AdaptiveStop, run_first, run, per_sample_answer,
             start: float) -> tuple[list[SampleOutcome], str]:
    """Anytime sampling: batch after batch until every sample ran, the deadline would pass during the
    next batch, or the answer's interval is narrow enough; the outcomes and what stopped it."""
    outcomes: list[SampleOutcome] = []
    for first in range(0, len(tasks), stop.batch_size):
        batch_start = time.perf_counter()
        outcomes += (run_first if first == 0 else run)(tasks[first:first + stop.batch_size])
        if len(outcomes) == len(tasks):
            break
        now = time.perf_counter()
        if stop.deadline_s is not None and (now - start) + (now - batch_start) > stop.deadline_s:
            return outcomes, "deadline"
        ok = [o for o in outcomes if o.ok]
        if stop.ci_width is not None and len(ok) >= stop.min_samples:
            fall = float(np.mean([per_sample_answer(o) for o in ok]))
            lo, hi = wilson_interval(fall, len(ok))
            if hi - lo <= stop.ci_width:
                return outcomes, "ci_width"
    return outcomes, "samples"


def check_some_sample_finished(outcomes: Sequence[SampleOutcome], budget_s: float | None) -> None:
    """An answer needs samples: when the budget cut off every sample (none finished), that is an
    error saying so (ConfigError naming budget_s), never an answer whose every probability is null."""
    if any(o.ok for o in outcomes) or not any(o.budget_stopped for o in outcomes):
        return
    cut = sum(o.budget_stopped for o in outcomes)
    failed = sum(not o.ok and not o.budget_stopped for o in outcomes)
    raise ConfigError("budget_s", f"no sample finished within the budget of {budget_s:g} s ({cut} cut off"
                                  + (f", {failed} failed" if failed else "") + "); raise the budget, or ask for fewer "
                                  "samples, objects or contact pairs")


def check_ci_width(ci_width: float | None, query: QuerySpec) -> None:
    """A target interval width needs an interval to watch: the fall or the any_fall query's."""
    if ci_width is not None and not (query.wants("fall") or query.wants("any_fall")):
        raise ConfigError("ci_width", "a target interval width needs the fall or any_fall query; add one to the "
                                      "queries or drop the target width")


def check_budget(budget_s: float | None) -> None:
    if budget_s is not None and (isinstance(budget_s, bool) or not isinstance(budget_s, (int, float))
                                 or not math.isfinite(budget_s) or budget_s <= 0):
        raise ConfigError("budget_s", f"must be a finite number of seconds > 0 (or none), got {shown(budget_s)}")


def predict(scene: Scene, model: ModelConfig, settings: SimSettings, query: QuerySpec, seed: int = 0,
            map_fn: MapFn | None = None, record_every: int = 0, record_samples: int | None = None,
            max_objects: int = DEFAULT_MAX_OBJECTS, stop: AdaptiveStop | None = None,
            budget_s: float | None = None, perceived=None, check: SelfCheck | None = DEFAULT_CHECK) -> Prediction:
    """Run the IPE on one scene and aggregate (failed rollouts are counted in ``failed_samples``).

    ``record_every``/``record_samples``: record trajectories (for rerun) every N simulation steps
    for the first M samples; recording never changes the outcome. ``stop``: anytime sampling
    (a deadline or a target interval width); ``Prediction.stopped_by`` says which rule ended it.
    ``budget_s``: the most wall seconds the prediction may take. A scene whose one rollout cannot
    fit is refused (ConfigError naming budget_s); samples still running when it runs out are cut
    off and the answer uses the rest (``stopped_by: "budget"``). Which samples finish in time is
    the one thing here that depends on timing.

    ``model.perception == "vision"``: the k noisy scenes are states of the vision posterior
    (``engine.vision``), from a chain run here (in a worker when ``map_fn`` is given, seeded from
    ``seed`` on a stream of its own) or taken from ``perceived`` (``vision.PerceivedScenes``).

    ``check``: how the answer checks its fast physics against the reference (``engine.fidelity``):
    unhealthy rollouts refined, ``check.verify_samples`` samples verified in the same map as the
    fast ones, everything rerun at the reference on disagreement; ``Prediction.fidelity`` says what
    happened. None or ``SelfCheck(enabled=False)``: the fast physics alone.
    """
    _check_seed(seed)
    check_budget(budget_s)
    check_fidelity_request(check)
    check_request(scene, query, max_objects, model=model, settings=settings, budget_s=budget_s)
    check_ci_width(None if stop is None else stop.ci_width, query)
    tasks = make_tasks(scene, model, settings, query, seed, record_every, record_samples)
    tasks, perceived = _from_perception(tasks, scene, model, seed, map_fn, perceived)
    if budget_s is not None:
        deadline = time.time() + budget_s
        tasks = [dataclasses.replace(t, deadline_unix_s=deadline) for t in tasks]

    def run(batch: list[SampleTask]) -> list[SampleOutcome]:
        return _run_tasks(batch, map_fn)

    at_reference = is_reference(settings)
    check = NO_CHECK if check is None or at_reference else check
    reference = reference_settings(settings.horizon_s)

    def run_verifying(samples: list[int], batch: list[SampleTask]) -> list[SampleOutcome]:
        """``batch`` with ``samples`` rerun at the reference in the same map, first (the longest
        tasks start first); their reruns go to ``verified``."""
        both = run([at_settings(tasks[i], reference) for i in samples] + batch)
        verified.update(zip(samples, both[:len(samples)]))
        return both[len(samples):]

    def run_first(batch: list[SampleTask]) -> list[SampleOutcome]:
        return run_verifying(list(range(verification_count(check, len(tasks)))), batch)

    verified: dict[int, SampleOutcome] = {}
    start = time.perf_counter()
    stopped_by = "samples"
    if stop is None or is_deterministic(scene, model):
        # the coverage sample runs beside the last quarter of the fast samples, picked from the rest
        split = look_ahead_split(check, len(tasks))
        outcomes: list[SampleOutcome] = run_first(tasks[:split])
        if split < len(tasks):
            outcomes += run_verifying(coverage_ahead(outcomes, verified, check, len(tasks)), tasks[split:])
    else:
        per_sample_answer = sample_fall_fraction if query.wants("fall") else sample_any_fall
        outcomes, stopped_by = _anytime(tasks, stop, run_first, run, per_sample_answer, start)
    check_some_sample_finished(outcomes, budget_s)
    if at_reference:
        report = FidelityReport("reference", settings=(("samples", settings.name),))
    else:
        outcomes, report = self_check(tasks[:len(outcomes)], outcomes, verified, check, reference, run, settings.name)
    wall_s = time.perf_counter() - start
    return _aggregate(scene, model, settings, query, seed, tasks, outcomes, wall_s, stopped_by, stop=stop,
                      budget_s=budget_s, perceived=perceived, fidelity=report)


def at_settings(task: SampleTask, settings: SimSettings) -> SampleTask:
    """The same sample (same seed, hence the same noisy scene) at other settings; a recorded sample
    keeps its frames the same simulated time apart."""
    every = task.record_every
    if every:
        every = max(1, round(every * task.settings.time_step_s / settings.time_step_s))
    return dataclasses.replace(task, settings=settings, record_every=every)


def self_check(tasks: list[SampleTask], outcomes: list[SampleOutcome], verified: dict[int, SampleOutcome],
               check: SelfCheck, reference: SimSettings, run: Callable[[list[SampleTask]], list[SampleOutcome]],
               fast_name: str) -> tuple[list[SampleOutcome], FidelityReport]:
    """Verify, refine and escalate (``engine.fidelity``): the outcomes the answer uses, and what happened.

    ``verified[i]`` is sample i rerun at ``reference``; ``run`` reruns tasks (through the map).
    """
    (result,) = self_check_many([checking(tasks, outcomes, verified, check, reference, fast_name)], reference, run)
    return result


Checking = Generator[list[SampleTask], list[SampleOutcome], tuple[list[SampleOutcome], FidelityReport]]


def self_check_many(checks: list[Checking], reference: SimSettings,
                    run: Callable[[list[SampleTask]], list[SampleOutcome]]) -> list[tuple[list[SampleOutcome],
                                                                                             FidelityReport]]:
    """Drive several checks (``checking``) together: each round, the tasks every unfinished check
    wants rerun go to ``run`` at ``reference`` in one batch (one map call keeps the workers busy),
    and each check gets its own back. The checks' results, in order."""
    results: list = [None] * len(checks)
    pending: dict[int, list[SampleTask]] = {}

    def advance(n: int, sent: list[SampleOutcome] | None) -> None:
        try:
            pending[n] = checks[n].send(sent)
        except StopIteration as done:
            pending.pop(n, None)
            results[n] = done.value

    for n in range(len(checks)):
        advance(n, None)
    while pending:
        order = sorted(pending)
        batch = [at_settings(t, reference) for n in order for t in pending[n]]
        reruns = run(batch) if batch else []
        at = 0
        for n in order:
            count = len(pending[n])
            advance(n, reruns[at:at + count])
            at += count
    return results


def checking(tasks: list[SampleTask], outcomes: list[SampleOutcome], verified: dict[int, SampleOutcome],
             check: SelfCheck, reference: SimSettings, fast_name: str) -> Checking:
    """The self-check of one answer's samples, as a generator: it yields the tasks it wants rerun at
    the reference, is sent their reruns, and returns the outcomes the answer uses and the report
    (``self_check`` and ``self_check_many`` drive it). ``verified[i]``: sample i already rerun."""
    parts = [("samples", fast_name)]
    if not check.enabled:
        return outcomes, FidelityReport("unverified", settings=tuple(parts))
        yield  # a generator even when it returns at once

    def differences() -> dict[int, np.ndarray]:
        return {i: difference(outcomes[i], ref) for i, ref in checked.items() if ref.ok and outcomes[i].ok}

    at_least = min(check.escalate_min_samples, len(tasks))

    def contradicted(compared: dict[int, np.ndarray]) -> bool:
        return contradicts(list(compared.values()), check.escalate_share, at_least)

    # 1. verification: the first samples with a fast outcome (a prediction's ran beside the fast
    # samples, in the first map; anytime sampling may have stopped before them)
    checked = {i: ref for i, ref in verified.items() if i < len(outcomes)}
    first = [i for i, o in enumerate(outcomes) if o.ok][:verification_count(check, len(outcomes))]
    missing = [i for i in first if i not in checked]
    if missing:
        checked.update(zip(missing, (yield [tasks[i] for i in missing])))
    if checked:
        parts.append(("verification", reference.name))
    # 2. refinement: the rollouts that ended unhealthy are rerun (a verified sample's rerun is at hand)
    reasons = {i: why for i, (task, outcome) in enumerate(zip(tasks, outcomes))
               if (why := unhealthy(outcome, scale_of(task.scene), check)) is not None}
    rerun = [i for i in reasons if i not in checked]
    if rerun:
        checked.update(zip(rerun, (yield [tasks[i] for i in rerun])))
    refined = {i: checked[i] for i in reasons if checked[i].ok}
    if refined:
        parts.append(("refined", reference.name))
    # the refined reruns alone moving some outcome by escalate_min_samples samples: that repair is
    # not small, and (chosen by how the fast rollouts ended) not unbiased; the reference answers
    repair = suspect([d for i, d in differences().items() if i in refined])
    # 3. confirmation: every sample rerun so far is a paired comparison, refined ones included (a
    # fast physics whose unhealthy rollouts topple what the reference's keep standing is wrong on
    # this scene, and replacing only those would bias the answer), and a suspect difference is
    # looked for again where it can show before it is believed; while nothing differs, one round
    # looks where a bias could hide from the samples compared so far (coverage)
    # samples verified beyond the first ones (``fidelity.coverage_ahead``) were coverage's picks
    cover = check.cover_samples - len([i for i in verified if i >= verification_count(check, len(tasks))])
    confirmations = 0
    while True:
        compared = differences()
        found = suspect(list(compared.values()))
        if repair >= at_least or contradicted(compared):
            break  # decided
        fast = {i: outcome_flags(o) for i, o in enumerate(outcomes) if i not in checked and o.ok}
        # a second confirmation round only while something is suspicious
        if found and confirmations < check.confirm_rounds and not (confirmations and found < 2):
            picked = confirmation_samples(fast, compared, check.confirm_samples)
            confirmations += 1
        elif not found and cover > 0:
            looked = [outcome_flags(outcomes[i]) for i in compared]
            picked = coverage_samples(fast, looked, at_least, cover)
            cover = 0
        else:
            break
        if not picked:
            break
        checked.update(zip(picked, (yield [tasks[i] for i in picked])))
    compared = differences()
    disagreeing = [i for i, d in compared.items() if d.any()]
    common = dict(verified_samples=len(compared), disagreeing_samples=len(disagreeing),
                  refined_samples=len(refined), refined_reasons=tuple((i, reasons[i]) for i in sorted(refined)))
    # every sample already has its reference rerun and some differ: the reference's answer is at hand
    known = bool(disagreeing) and len(compared) == len(outcomes)
    if not contradicted(compared) and repair < at_least and not known:
        # a confirmation or a coverage rerun the budget cut off neither confirmed nor dismissed a bias
        unconfirmed = any(o.budget_stopped for o in checked.values())
        verdict = "verified" if first and all(i in compared for i in first) and not unconfirmed else "unverified"
        return merge(outcomes, refined), FidelityReport(verdict, settings=tuple(parts), **common)
    # 4. escalation: contradicted on this scene, so every sample at the reference
    done = dict(checked)
    rest = [i for i in range(len(outcomes)) if i not in done and not outcomes[i].skipped]
    if rest:
        done.update(zip(rest, (yield [tasks[i] for i in rest])))
    parts.append(("escalation", reference.name))
    if any(o.budget_stopped for o in done.values()):
        return merge(outcomes, refined), FidelityReport("contradicted", settings=tuple(parts), **common)
    return merge(outcomes, done), FidelityReport("escalated", escalated_samples=len(done), settings=tuple(parts),
                                                 **common)


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
    prediction = aggregate(scene, outcomes, query=query,
                           deterministic=is_deterministic(scene, model), samples_requested=len(tasks),
                           wall_s=wall_s, request=request)
    if fidelity is not None:
        prediction = dataclasses.replace(prediction, fidelity=fidelity.verdict, refined_samples=fidelity.refined_samples,
                                         self_check=fidelity.to_dict())
    if prediction.stopped_by == "budget":
        return prediction
    return dataclasses.replace(prediction, stopped_by=stopped_by)


def predict_many(requests: Sequence[tuple[Scene, ModelConfig, int]], settings: SimSettings, query: QuerySpec,
                 map_fn: MapFn | None = None, max_objects: int = DEFAULT_MAX_OBJECTS) -> list[Prediction]:
    """``[predict(scene, model, settings, query, seed, map_fn) for scene, model, seed in requests]``,
    with every sample of every request in one ``map_fn`` call: equal answers (each request keeps its
    own seeds), but no worker waits for a prediction's last sample before the next one starts, and a
    cluster's round trip is paid once instead of per prediction. For batch work (the paper's
    analyses); ``wall_s`` of each answer is the whole map's time shared out by its samples.
    Requests whose perception draws from a posterior run one by one (each needs its chain first;
    depth perception, whose images only the caller has, is refused). Batch answers are
    not self-checked (``fidelity: "unverified"``): the paper's analyses reproduce fixed settings,
    and the check's extra samples would change what a resumable run stores.
    """
    unchecked = FidelityReport("reference" if is_reference(settings) else "unverified",
                               settings=(("samples", settings.name),))
    requests = list(requests)
    answers: list[Prediction | None] = [None] * len(requests)
    batched: list[tuple[int, list[SampleTask]]] = []
    for i, (scene, model, seed) in enumerate(requests):
        if perception_source(model.perception).posterior:  # its chain first, then its samples
            answers[i] = predict(scene, model, settings, query, seed, map_fn, max_objects=max_objects, check=None)
            continue
        _check_seed(seed)
        check_request(scene, query, max_objects)
        batched.append((i, make_tasks(scene, model, settings, query, seed)))
    everything = [task for _, tasks in batched for task in tasks]
    start = time.perf_counter()
    outcomes = _run_tasks(everything, map_fn)
    wall_s = time.perf_counter() - start
    first = 0
    for i, tasks in batched:
        scene, model, seed = requests[i]
        mine = outcomes[first:first + len(tasks)]
        first += len(tasks)
        answers[i] = _aggregate(scene, model, settings, query, seed, tasks, mine,
                                wall_s * len(tasks) / max(1, len(everything)), "samples", fidelity=unchecked)
    return answers  # type: ignore[return-value]
