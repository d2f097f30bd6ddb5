"""Answering every variant of a question with common random numbers, in one map or sequentially
until decided (``decide``)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

from ..config import ModelConfig, SimSettings
from ..query import QUERIES, QuerySpec
from ..sampling.decide import Sequential, Tally
from ..errors import ConfigError
from ..sampling.perturb import is_deterministic, position_sigmas_m
from ..checking.fidelity import (FidelityReport, SelfCheck, check_request as check_fidelity_request, is_reference,
                                 reference_settings, refine_in_task)
from ..sampling.montecarlo import (MonteCarlo, Plan, check_budget, check_some_sample_finished, child_seeds,
                                   far_over_budget, mapped, together)
from ..predict import Context, Request, rollout_cost
from ..checking.self_check import checking
from ..scene.bodies import Scene, Table
from ..scene.validation import validate_scene
from ..query.contact import check_pairs
from ..results.outcome import SampleOutcome, rigid_reruns
from ..sampling.rollout import take_refined
from .answers import (QUESTION_QUERIES, Alone, Answers, aggregate_given, aggregate_variant, caused, draws_noise, fell,
                      ran, stood)
from .checks import check_action, validated_variants
from .geometry import affected_regions, groups, reached
from .kinds import DEFAULT_SAFE_BELOW, Action, Place, Push, Remove, label_of
from .variants import VariantTask, lost, run_variants, skipped


def ask(scene: Scene, actions: list[Action], request: Request, context: Context | None = None) -> Answers:
    """Answer every variant with common random numbers (see the module docstring), as ``request``
    asks (its model, settings, seed, budget and check) where ``context`` says (its map, its
    recording, its progress callback, the perceived scenes). Removals that cannot change anything are
    answered from the scene's own samples (a variant "as is" is added for them when it is not asked).

    The question's queries ride in ``request.query`` (``questions.question_spec`` makes one):
    ``fall``: what falls (without it, ``any_fall``: a rollout ends at the first fall); ``direction``:
    also where things fall (rollouts then run until everything rests); ``bump``: also which objects
    end off the table (the scene must stand on one); ``contact`` with its pairs: P(A touches B) per
    variant (every variant is then simulated); any other registered query, with its parameters
    (``VariantAnswer.query_answers``; every variant simulated).

    ``request.stop``: a ``Sequential`` rule answers in batches until it decides each variant,
    simulating variants only in samples where the scene as it is stands (``decide``); it needs an
    "as is" variant and is ignored without noise. ``context.on_progress`` is called after each batch
    with what is decided so far (``progress_dict``); whatever it raises ends the question there.
    ``request.check`` (e.g. ``fidelity.DEFAULT_CHECK``): each simulated variant's samples check
    themselves against the reference physics as a prediction's do (the checks of all variants share
    each round's map call), and a contradicted variant is answered at the reference; None: each
    variant says "unverified" (it costs 1.5-6x a question's time, benchmarks/HISTORY.md).
    ``context.record_every`` / ``record_samples``: keep the trajectories of the first samples of every
    simulated variant (for rerun), in ``Answers.recorded``. ``context.perceived``: scenes drawn from a
    perception's posterior: sample i of every variant starts from ``perceived.scenes[i]`` and the
    model's sigma is not drawn (the posterior is the noise), as in a prediction from that perception."""
    context = context or Context()
    spec, model, settings, seed = request.query, request.model, request.settings, request.seed
    budget_s, check, sequential = request.budget_s, request.check, request.stop
    if sequential is not None and not isinstance(sequential, Sequential):
        raise ConfigError("stop", "a question stops by a Sequential rule (engine.sampling.decide); anytime sampling "
                                  "(AdaptiveStop) is for predictions")
    map_fn, on_progress, perceived, record_every = context.map_fn, context.on_progress, context.perceived, \
        context.record_every
    record_samples = math.inf if context.record_samples is None else context.record_samples
    _check_question(scene, actions, model, budget_s, check, spec)
    if perceived is not None:
        model = dataclasses.replace(model, sigma_m=0.0)
    plan = _plan(scene, actions, model, settings, budget_s, spec, perceived)
    loop = MonteCarlo(run_variants, lost, map_fn, budget_s)  # the budget counts from here
    seeds = child_seeds(seed, plan.samples)
    refine = refine_in_task(check, settings)  # an unhealthy variant's rerun runs in its sample's task

    def tasks(indices, variants: list[int]) -> list[VariantTask]:
        return [VariantTask(scene=scene if perceived is None else perceived.scenes[i], model=model, settings=settings,
                            query=plan.query, index=i, seed=seeds[i],
                            actions=tuple(plan.simulated_actions[j] for j in variants),
                            regions=tuple(plan.regions[j] for j in variants),
                            record_every=record_every if i < record_samples else 0, refine=refine)
                for i in indices]

    validated = validated_variants([scene] if perceived is None else perceived.scenes, plan.simulated_actions,
                                   model, settings, check)
    per_sample, decisions, reports = loop.drive(_question(plan, tasks, settings, sequential, check, budget_s, scene,
                                                          on_progress, validated))
    answers, scene_alone = _answers(scene, actions, plan, per_sample, decisions, reports)
    stopped = "budget" if any(r.budget_stopped for s in per_sample for r in s) else "samples"
    recorded = {label_of(a): [(i, s[j]) for i, s in enumerate(per_sample) if s[j].ok and ran(s[j]).trajectory is not None]
                for j, a in enumerate(plan.simulated_actions)} if record_every else {}
    return Answers(scene.name, tuple(answers), plan.samples, loop.elapsed_s(), stopped, recorded, scene_alone)


def _question(plan: "_Plan", tasks, settings: SimSettings, sequential: Sequential | None, check: SelfCheck | None,
              budget_s: float | None, scene: Scene, on_progress, validated: list[str]) -> Plan:
    """A question's samples, then every simulated variant's self-check, as a plan (``montecarlo``):
    returns per sample every variant's outcome, the sequential decisions (label -> (decision, why it
    stopped, samples drawn)) and each variant's check report. ``validated[j]``: why variant j needs
    no verification (``checks.validated_variants``), or ""."""
    k, simulated_actions, as_is = plan.samples, plan.simulated_actions, plan.as_is
    decisions: dict[str, tuple[str | None, str, int]] = {}
    if sequential is None or plan.deterministic or as_is is None:
        per_sample = yield tasks(range(k), list(range(len(simulated_actions))))
    else:
        per_sample, decisions = yield from _sequentially(tasks, simulated_actions, as_is, k, sequential, scene,
                                                         on_progress)
    check_some_sample_finished([r for s in per_sample for r in s], budget_s)
    reports = yield from _check_variants(per_sample, simulated_actions, tasks, settings, check, validated)
    if sequential is not None and any(r.verdict == "escalated" or r.refined_samples for r in reports.values()):
        decisions = _decide_again(decisions, per_sample, simulated_actions, as_is, sequential)
    return per_sample, decisions, reports


def _check_question(scene: Scene, actions: list[Action], model: ModelConfig, budget_s: float | None,
                    check: SelfCheck | None, spec: QuerySpec) -> None:
    """Everything a question asks, checked before anything is simulated."""
    validate_scene(scene)  # the queries checked themselves (QuerySpec; questions.question_spec)
    check_budget(budget_s)
    check_fidelity_request(check)
    for i, action in enumerate(actions):
        check_action(scene, action, f"actions[{i}]")
        if not model.object_noise and isinstance(action, Push) and draws_noise(scene, action, model):
            raise ConfigError(f"actions[{i}]", "the ground truth takes a push exactly as given, but this one has "
                                               "noise of its own (a direction or speed sigma); drop it, or ask "
                                               "without the ground truth")
    if "bump" in spec.queries and not isinstance(scene.support, Table):
        raise ConfigError("fell_off", f"{scene.name!r} stands on a floor: nothing can fall off it (ask it of a "
                                      "scene on a table)")
    _check_contact(scene, actions, spec.contact_pairs)


@dataclass(frozen=True)
class _Plan:
    """What a question simulates: the variants run (``simulated_actions``; the asked ones that are
    ``trivial`` are read from "as is" instead), the objects each can affect (``regions``, None: all),
    the queries, and the samples (one when nothing draws noise)."""

    simulated_actions: list[Action]
    trivial: list[bool]
    regions: tuple[frozenset[str] | None, ...]
    everything: frozenset[str]
    query: QuerySpec
    deterministic: bool
    samples: int

    @property
    def as_is(self) -> int | None:
        return self.simulated_actions.index(None) if None in self.simulated_actions else None


def _plan(scene: Scene, actions: list[Action], model: ModelConfig, settings: SimSettings, budget_s: float | None,
          spec: QuerySpec, perceived=None) -> _Plan:
    directions, contact = "direction" in spec.queries, spec.contact_pairs
    queries = tuple(q for q in QUERIES if q in spec.queries and q not in QUESTION_QUERIES)
    margin = 3 * float(position_sigmas_m(scene, model).max(initial=0.0))  # noise can close gaps this wide
    if perceived is not None:  # and the posterior's samples by how far they moved two objects apart
        margin += 2 * _farthest_moved_m(scene, perceived.scenes)
    everything = frozenset(b.name for b in scene.dynamic_objects)
    # a pushed support can slide every group into every other
    scene_groups = [everything] if model.pushes else groups(scene, margin)
    # a removal that nothing else is within reach of cannot change anything: the rest of the scene does
    # what it does anyway (read from "as is"). Touching is not enough to be left out: a counterweight
    # with nothing on it still holds down what it rests on, and a gap closes when the object above drops.
    trivial = [isinstance(a, Remove) and reached(scene_groups, a.names) <= set(a.names) and not contact
               and not queries for a in actions]
    simulated_actions = [a for a, t in zip(actions, trivial) if not t]
    if any(trivial) and None not in simulated_actions:
        simulated_actions.append(None)
    if budget_s is not None:
        cost = rollout_cost(scene, model, settings, len(contact))
        if far_over_budget(cost.seconds * max(1, len(simulated_actions)), budget_s):
            raise ConfigError("budget_s", f"one sample of these {len(simulated_actions)} variants takes up to "
                                          f"~{cost.seconds * len(simulated_actions):.3g} s, far more than the budget of "
                                          f"{budget_s:g} s; ask fewer variants or raise the budget")
    regions = affected_regions(scene, simulated_actions, margin, scene_groups, model.pushes)
    # a removal read from "as is" needs each other object's outcome there; a direction, what fell
    what_falls = "fall" in spec.queries or any(trivial) or directions
    asked = (spec.queries - {"fall", "any_fall"}) | {"fall" if what_falls else "any_fall"}
    query = QuerySpec(queries=frozenset(asked), fall_threshold_fraction=spec.fall_threshold_fraction,
                      contact_pairs=spec.contact_pairs, parameters=tuple(p for p in spec.parameters if p[0] in asked))
    for name in queries:
        QUERIES[name].check(scene, query)
    # no noise anywhere (scene, model, nor an action's own): one rollout per variant says everything
    deterministic = is_deterministic(scene, model) and not any(draws_noise(scene, a, model)
                                                               for a in simulated_actions) and perceived is None
    samples = 1 if deterministic else model.samples
    if perceived is not None and len(perceived.scenes) < samples:
        raise ConfigError("samples", f"{len(perceived.scenes)} perceived scenes for {samples} samples")
    return _Plan(simulated_actions, trivial, regions, everything, query, deterministic, samples)


def _farthest_moved_m(scene: Scene, scenes) -> float:
    """The farthest any dynamic object of ``scenes`` is from where ``scene`` has it."""
    given = {b.name: b.position_m for b in scene.dynamic_objects}
    return max((math.dist(b.position_m, given[b.name]) for s in scenes for b in s.dynamic_objects
                if b.name in given), default=0.0)


def _answers(scene: Scene, actions: list[Action], plan: _Plan, per_sample, decisions,
             reports) -> tuple[list, Alone | None]:
    """Each asked variant's answer, in the order asked, and the scene left alone."""
    deterministic, as_is = plan.deterministic, plan.as_is
    by_variant = {label_of(a): dataclasses.replace(
        aggregate_variant(label_of(a), a, [s[j] for s in per_sample], deterministic=deterministic, scene=scene,
                          query=plan.query),
        not_simulated=() if plan.regions[j] is None else tuple(sorted(plan.everything - plan.regions[j])),
        **_fidelity(reports.get(j)))
        for j, a in enumerate(plan.simulated_actions)}
    stands = []
    if as_is is not None:
        stands = [stood(s[as_is]) for s in per_sample]
        for j, a in enumerate(plan.simulated_actions):
            by_variant[label_of(a)] = dataclasses.replace(
                by_variant[label_of(a)], caused_fall_probability=caused(per_sample, j, as_is),
                given_stands=aggregate_given(
                    [s[j] for s, ok in zip(per_sample, stands) if ok], deterministic=deterministic))
    for label, (decision, why, drawn) in decisions.items():
        by_variant[label] = dataclasses.replace(by_variant[label], decision=decision, stopped_by=why,
                                                samples_drawn=drawn)
    answers = []
    for action, is_trivial in zip(actions, plan.trivial):
        if not is_trivial:
            answers.append(by_variant[label_of(action)])
            continue
        # nothing rests on it: the rest of the scene does what it does anyway, read from "as is"
        others = [j for j, n in enumerate(b.name for b in scene.dynamic_objects) if n not in action.names]
        results = [_without(r, others) for r in (s[as_is] for s in per_sample)]
        answers.append(dataclasses.replace(
            aggregate_variant(label_of(action), action, results, deterministic=deterministic), simulated=False,
            caused_fall_probability={n: 0.0 for j, n in enumerate(b.name for b in scene.dynamic_objects)
                                     if j in others},
            given_stands=aggregate_given([r for r, ok in zip(results, stands) if ok], deterministic=deterministic)))
    scene_alone = None
    if as_is is not None:
        alone = by_variant["as_is"]
        scene_alone = Alone(alone.any_fall_probability, alone.any_fall_probability_ci95, sum(stands),
                           alone.any_fall_probability_ci95 is not None
                           and alone.any_fall_probability_ci95[0] > DEFAULT_SAFE_BELOW)
    return answers, scene_alone


def _check_contact(scene: Scene, actions: list[Action], pairs) -> None:
    """Contact pairs name objects of the scene, placed objects, or the support."""
    check_pairs(pairs, scene, tuple(a.body.name for a in actions if isinstance(a, Place)))


def _check_variants(per_sample: list[list[SampleOutcome]], actions: list[Action], tasks, settings: SimSettings,
                    check: SelfCheck | None, validated: list[str]) -> Plan:
    """Each simulated variant's self-check (``self_check.checking``), all in the same rounds; the
    checked outcomes replace the fast ones in ``per_sample``. A variant inside the validated envelope
    (``validated[j]``) verifies and covers nothing: only its unhealthy rollouts are rerun. Returns
    variant index -> what its check did."""
    if is_reference(settings):
        return {j: FidelityReport("reference", settings=(("samples", settings.name),),
                                  rigid_reruns=rigid_reruns(row[j] for row in per_sample)) for j in range(len(actions))}
    if check is None or not check.enabled or not per_sample:
        return {j: FidelityReport("unverified", settings=(("samples", settings.name),)) for j in range(len(actions))}
        yield  # a plan even when it needs nothing run
    reference = reference_settings(settings.horizon_s)
    samples = range(len(per_sample))
    # reruns made in their sample's task, taken out of the outcomes they came with
    reruns = []
    for j in range(len(actions)):
        outcomes, taken = take_refined(samples, [row[j] for row in per_sample])
        reruns.append(taken)
        for row, outcome in zip(per_sample, outcomes):
            row[j] = outcome
    unverified = dataclasses.replace(check, verify_samples=0, cover_samples=0)
    checks = [mapped(checking(tasks(samples, [j]), [row[j] for row in per_sample], {},
                              unverified if validated[j] else check, reference, settings.name, validated[j],
                              rerun=reruns[j]), _only)
              for j in range(len(actions))]
    reports = {}
    for j, (outcomes, report) in enumerate((yield from together(checks))):
        for row, outcome in zip(per_sample, outcomes):
            row[j] = outcome
        reports[j] = report
    return reports


def _only(outcomes: list[SampleOutcome]) -> SampleOutcome:
    """The outcome of a variant task that ran one variant (as the self-check's reruns do)."""
    (only,) = outcomes
    return only


def _fidelity(report: FidelityReport | None) -> dict:
    if report is None:
        return {}
    return dict(fidelity=report.verdict, self_check=report.to_dict())


def _decide_again(decisions: dict, per_sample: list[list[SampleOutcome]], actions: list[Action], as_is: int,
                  sequential: Sequential) -> dict:
    """The decisions read again from the checked outcomes: a variant the check escalated or refined
    may fall on the other side of its threshold now, or on neither (None); a changed decision
    stopped by "checked"."""
    counts = {label_of(a): _Counts() for j, a in enumerate(actions) if j != as_is}
    for row in per_sample:
        for j, a in enumerate(actions):
            if j != as_is:
                counts[label_of(a)].add(row[j])
    tallies = {label: c.tally() for label, c in counts.items()}
    decided = {label for label, (decision, _, _) in decisions.items() if decision is not None}
    again = sequential.rule.decide(tallies, decided)
    out = {}
    for label, (decision, why, drawn) in decisions.items():
        now = again.get(label) if label in decided else decision
        out[label] = (now, why if now == decision else "checked", drawn)
    return out


def _without(outcome: SampleOutcome, kept: list[int]) -> SampleOutcome:
    """The scene-as-is outcome read for a removal nothing rests on: only the ``kept`` objects."""
    if not outcome.ok:
        return outcome
    r = ran(outcome)
    # the per-object values a question reads from "as is" (``_plan``: what falls, what fell off)
    values = {name: value[kept] if name in ("fallen", "fell_off") else value for name, value in r.values.items()}
    rollout = dataclasses.replace(r, final_positions_m=r.final_positions_m[kept],
                                  final_orientations_xyzw=r.final_orientations_xyzw[kept], values=values,
                                  trajectory=None)
    return dataclasses.replace(outcome, rollouts=(rollout,), names=tuple(outcome.names[j] for j in kept))


#: variants per task in a sequential batch: enough to amortise the shared draw and separation each
#: task redoes, few enough that standing samples' variants spread over the workers
VARIANTS_PER_TASK = 4


def _sequentially(tasks, actions: list[Action], as_is: int, k: int, sequential: Sequential, scene: Scene,
                  on_progress: Callable[[dict], None] | None = None) -> Plan:
    """A plan (``montecarlo``): batches of samples until the rule has decided every variant or k samples are drawn. Each
    batch runs the scene as it is first, then the undecided variants of the samples in which it
    stood, a few variants per task (the work of one sample varies too much - one rollout or all of
    them - to spread by samples); a variant not run in a sample is a skipped result. Returns every
    sample's results (in ``actions`` order) and, per variant label, (decision, why it stopped,
    samples drawn for it).

    With more than one variant undecided, the next batch's scene-as-it-is samples run in the same
    map call as this batch's variants (one map call per batch instead of two, no worker idle while
    the few as-is rollouts finish). Nothing depends on them until the next batch: when the rule
    decides everything first, they are dropped, so the answer is the one batch by batch."""
    others = [j for j in range(len(actions)) if j != as_is]
    active = set(others)
    decisions: dict[str, tuple[str | None, str, int]] = {}
    per_sample: list[list[SampleOutcome]] = []
    # counted as the batches come (recounting every sample at every look would grow with k x looks)
    counts = {label_of(actions[j]): _Counts() for j in others}

    def batch_from(first: int) -> range:
        return range(first, min(k, first + sequential.batch_samples))

    def as_is_of(indices: range, results) -> dict[int, SampleOutcome]:
        return dict(zip(indices, (only for (only,) in results)))

    batch = batch_from(0)
    alone: dict[int, SampleOutcome] = {}  # this batch's scene-as-it-is samples
    while len(per_sample) < k and active:
        if not alone:  # not run ahead beside the last batch's variants
            alone = as_is_of(batch, (yield tasks(batch, [as_is])))
        rows = {}
        for i in batch:
            rows[i] = [skipped(i, "the scene fell as it is" if j in active else "decided") for j in range(len(actions))]
            rows[i][as_is] = alone[i]
        standing = [i for i in batch if stood(rows[i][as_is])]
        running = sorted(active)
        chunks = [running[c:c + VARIANTS_PER_TASK] for c in range(0, len(running), VARIANTS_PER_TASK)]
        jobs = [(i, chunk) for i in standing for chunk in chunks]
        work = [task for i, chunk in jobs for task in tasks([i], chunk)]
        ahead = batch_from(batch.stop) if len(active) > 1 else range(0)
        results = (yield work + tasks(ahead, [as_is])) if work or ahead else []
        for (i, chunk), variant_results in zip(jobs, results[:len(jobs)]):
            for j, result in zip(chunk, variant_results):
                rows[i][j] = result
        alone = as_is_of(ahead, results[len(jobs):])
        for i in batch:
            per_sample.append(rows[i])
            for j in running:
                counts[label_of(actions[j])].add(rows[i][j])
        if any(r.budget_stopped for i in batch for r in rows[i]):
            break
        tallies = {label: c.tally() for label, c in counts.items()}
        labels = {label_of(actions[j]): j for j in active}
        for label, decision in sequential.rule.decide(tallies, set(labels)).items():
            decisions[label] = (decision, "decided", len(per_sample))
            active.discard(labels[label])
        if len(per_sample) < k:  # at the cap they are undecided anyway ("cap")
            labels = {label_of(actions[j]): j for j in active}
            for label in sequential.rule.undecidable(tallies, set(labels), k - len(per_sample)):
                decisions[label] = (None, "undecidable", len(per_sample))
                active.discard(labels[label])
        if on_progress is not None:
            on_progress(progress_dict(scene.name, k, len(per_sample), decisions,
                                      [label_of(actions[j]) for j in sorted(active)], tallies))
        batch = batch_from(batch.stop)
    budget = any(r.budget_stopped for row in per_sample for r in row)
    for j in active:
        decisions[label_of(actions[j])] = (None, "budget" if budget else "cap", len(per_sample))
    return per_sample, decisions


def progress_dict(scene: str, k: int, drawn: int, decisions: dict, undecided: list[str],
                  tallies: dict[str, Tally]) -> dict:
    """A partial answer: the samples drawn so far (of at most k), each variant done sampling with its
    decision (None: "undecidable", ``decide``), why it stopped and the samples it used, and the
    variants still sampling with their running P(anything falls)."""
    def running(label):
        t = tallies[label]
        return {"label": label, "samples": t.samples,
                "any_fall_probability": None if t.samples == 0 else t.any_falls / t.samples}
    return {"scene": scene, "samples_requested": k, "samples_drawn": drawn,
            "decided": [{"label": label, "decision": d, "stopped_by": why, "samples_drawn": n,
                         "samples": tallies[label].samples} for label, (d, why, n) in decisions.items()],
            "undecided": [running(label) for label in undecided]}


class _Counts:
    """A variant's outcomes so far (skipped and failed samples left out), as a decide.Tally."""

    def __init__(self):
        self.samples, self.any_falls, self.object_falls = 0, 0, {}

    def add(self, result: SampleOutcome) -> None:
        if not result.ok:
            return
        self.samples += 1
        self.any_falls += fell(ran(result))
        if ran(result).fallen is None:  # what falls not asked
            return
        for name, fallen in zip(result.names, ran(result).fallen):
            self.object_falls[name] = self.object_falls.get(name, 0) + bool(fallen)

    def tally(self) -> Tally:
        return Tally(self.samples, self.any_falls, dict(self.object_falls))
