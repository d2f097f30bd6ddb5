"""``ipe predict``: answer every scene of a file (or the built-in example), as a table or JSON lines,
from sigma, vision or a depth camera's images, on local worker processes or a Dask cluster."""

from __future__ import annotations

import argparse
import contextlib

import dataclasses
import json
import math
import sys

from .cli_evidence import chosen_perception, describe
from .cli_inputs import given_request_arguments, typed_option
from .cli_queries import given_query_parameters
from .engine import ConfigError, Context, Prediction, Request, SceneError, WorkerPool, load_scenes, predict
from .engine.config import anytime_batch_size, default_workers
from .engine.inputs import spelled
from .engine.sampling.perturb import is_deterministic
from .engine.query import QUERIES
from .engine.request import build_request
from .engine.predict import check_request
from .engine.scene.format import RefusedScene
from .engine.scene.mesh_repair import repaired_sources
from .progress import steps

#: the exit status of a command refused for its input (argparse's own)
EXIT_BAD_INPUT = 2

#: a rollout ending deeper than this fraction of a body inside another is worth a note in the table
NOTABLE_PENETRATION = 0.01

def _number_or_dash(value, spec: str = ".3f", none: str = "-") -> str:
    return none if value is None else format(value, spec)


def format_table(predictions: list[Prediction]) -> str:
    """A readable fixed-width table of predictions."""
    header = (f"{'scene':<34} {'k':>4} {'P(fall)':>7} {'95% CI':>15} {'dir(deg)':>8} {'decisive':>8} "
              f"{'far(m)':>7} {'fail':>4} {'wall(s)':>7}")
    lines = [header, "-" * len(header)]
    for p in predictions:
        ci = "-" if p.fall_fraction_ci95 is None else f"[{p.fall_fraction_ci95[0]:.2f}, {p.fall_fraction_ci95[1]:.2f}]"
        direction = None if p.direction_rad is None else math.degrees(p.direction_rad)
        lines.append(f"{p.scene[:34]:<34} {p.samples:>4} {_number_or_dash(p.fall_fraction):>7} {ci:>15} "
                     f"{_number_or_dash(direction, '.0f'):>8} {_number_or_dash(p.direction_decisiveness, '.2f'):>8} "
                     f"{_number_or_dash(p.far_m, '.2f'):>7} {p.failed_samples:>4} {p.wall_s:>7.2f}")
        if p.any_fall_probability is not None:
            lo, hi = p.any_fall_probability_ci95
            lines.append(f"{'':<34} P(anything falls): {p.any_fall_probability:.3f} [{lo:.2f}, {hi:.2f}]")
        if p.fell_off_fraction_by_group is not None:
            groups = ", ".join(f"{g}: {v:.2f}" for g, v in p.fell_off_fraction_by_group.items())
            lines.append(f"{'':<34} fell off by group: {groups}; {p.bump_group} share: {_number_or_dash(p.bump_ratio, '.2f')}")
        for name in p.request.get("queries", ()):
            if name in QUERIES and p.samples:
                lines.extend(f"{'':<34} {line}" for line in QUERIES[name].describe(p))
        if p.property_influence:
            lines.append(f"{'':<34} {describe_influence(p.property_influence[0])}")
        if p.failure_reasons:
            lines.append(f"{'':<34} failures: {'; '.join(p.failure_reasons)}")
        if p.fidelity is not None and p.fidelity not in ("verified", "validated") or p.refined_samples:
            lines.append(f"{'':<34} fidelity: {describe_fidelity(p)}")
        if (p.max_penetration_fraction or 0) > NOTABLE_PENETRATION or (p.max_energy_gain_j or 0) > 0:
            lines.append(f"{'':<34} numerical health: a body ended {p.max_penetration_fraction:.1%} of its size inside "
                         f"another; a rollout gained {p.max_energy_gain_j:.3g} J")
    return "\n".join(lines)


def describe_influence(row: dict) -> str:
    """One line on the uncertain property that moves the answer most (``sampling.influence``)."""
    what = f"P({row['object']} falls)" if row["outcome"] == "fall_probability" else f"{row['object']}'s travel (m)"
    return (f"most influential: {row['property']} (median {row['median']:.3g}): {what} {row['below_median']:.2f} "
            f"below it, {row['above_median']:.2f} above (+-{2 * row['difference_se']:.2f}); measure it first")


#: ``FidelityReport.escalated_because``, in words
ESCALATED_BECAUSE = {"beyond_tolerance": "a bias beyond the tolerance",
                     "undecided": "a bias still undecided when the check's rounds were spent",
                     "refined": "the reruns of unhealthy rollouts alone moved an outcome",
                     "every_sample_compared": "every sample compared"}


def describe_fidelity(p: Prediction) -> str:
    """One line on what the self-check did (engine.checking.fidelity)."""
    report = p.self_check or {}
    because = ", ".join(ESCALATED_BECAUSE.get(r, r) for r in report.get("escalated_because", ()))
    disagreed = f"the reference physics disagreed with the fast one{f' ({because})' if because else ''}"
    strata = report.get("escalated_strata")
    rerun = (f"the {report.get('escalated_samples', 0)} disputed samples rerun at the reference, the others kept"
             if strata else "every sample rerun at the reference")
    text = {"verified": "verified against the reference physics",
            "validated": "inside the envelope where the fast physics was validated: not rerun at the reference",
            "escalated": f"{disagreed}: {rerun}",
            "contradicted": f"{disagreed} and the budget ran out before it could answer: do not act on this answer",
            "unverified": "not checked against the reference physics",
            "reference": "computed at the reference settings"}.get(p.fidelity or "", str(p.fidelity))
    if p.refined_samples:
        text += f"; {p.refined_samples} unhealthy rollout(s) rerun at the reference"
    return text


def prediction_json(prediction: Prediction) -> str:
    return json.dumps(prediction.to_dict(), allow_nan=False, sort_keys=True)


def sample_map(scheduler: str | None, workers: int):
    """Where samples run: a Dask cluster (``--scheduler`` or $IPE_DASK_SCHEDULER), worker processes
    here, or (0 workers) this process. Returns the pool-like object (with ``map`` and ``close``) or None."""
    from .engine.compute.cluster import DaskMap, scheduler_address

    address = scheduler_address(scheduler)
    if address is not None:
        try:
            return DaskMap(address)
        except ConfigError as exc:
            raise ConfigError("--scheduler", exc.problem) from None
    if workers < 0:
        raise ConfigError("--workers", f"must be >= 0, got {workers}")
    return WorkerPool(workers) if workers > 0 else None


def add_batch_options(parser: argparse.ArgumentParser) -> None:
    """Where a batch command's samples run, and where they are kept (``batch_map`` reads them)."""
    parser.add_argument("--workers", type=int, default=default_workers(), help="worker processes (0: in-process)")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="run the samples on a Dask cluster (default: $IPE_DASK_SCHEDULER, else --workers here)")
    parser.add_argument("--resume", default=None, metavar="DIR",
                        help="keep every sample's result in DIR (keyed by scene, settings and seed); a run started "
                             "again with the same DIR computes only what is missing")


@contextlib.contextmanager
def batch_map(scheduler: str | None, workers: int, resume: str | None):
    """(map, store) for a batch command (``ipe experiment``, ``ipe fit``): samples on a cluster, the
    workers here or this process (``sample_map``), kept in ``resume``'s store when given (store None
    otherwise); the pool closed at the end."""
    pool = sample_map(scheduler, workers)
    map_fn = pool.map if pool else None
    store = None
    if resume is not None:
        from .engine.compute.store import ResumableMap

        store = ResumableMap(resume, map_fn)
        map_fn = store.map
    try:
        yield map_fn, store
    finally:
        if pool is not None:
            pool.close()


def stored_line(store, resume: str) -> str:
    return (f"  {store.hits} results read back from {resume}, {store.computed} computed"
            + (f", {store.rejected} stored entries refused" if store.rejected else ""))


def run_predictions(scenes, request: Request, workers: int, emit, scheduler: str | None = None, evidence=None) -> None:
    """``request`` of every scene, on ``workers`` local processes or the Dask ``scheduler``'s;
    ``evidence``: what the model's perception draws its scenes given (``engine.evidence``): its
    chain runs inside ``predict``, on the samples' workers, within its share of the budget."""
    pool = sample_map(scheduler, min(workers, max(1, request.model.samples)) if workers > 0 else workers)
    if request.stop is not None:  # anytime batches as wide as the workers
        from .engine.compute.cluster import DaskMap

        parallel = pool.workers if isinstance(pool, DaskMap) else workers
        request = dataclasses.replace(request, stop=dataclasses.replace(request.stop,
                                                                        batch_size=anytime_batch_size(parallel)))
    try:
        for scene in steps(scenes, "predict") if len(scenes) > 1 else scenes:
            emit(predict(scene, request, Context(map_fn=pool.map if pool else None, evidence=evidence)))
    finally:
        if pool is not None:
            pool.close()


def cmd_predict(args) -> int:
    refused: list[RefusedScene] = []  # scenes of the file that cannot be answered: reported, the rest answered
    try:
        # a --budget typed bounds each mesh's first decomposition too (cached after: later runs cost
        # nothing); without it a mesh decomposes however long it takes, once (the way to fill the cache)
        scenes = load_scenes(args.path, towers=args.tower, on_refused=refused.append,
                             decompose_within_s=args.budget_s if typed_option(args, "--budget") else None)
    except SceneError:
        _report_refused(args, refused)  # none of the file's scenes read: each refusal said before the verdict
        raise
    for scene in scenes:  # an open mesh answered as a repaired solid: said once, before the answers
        for name, source in repaired_sources(scene).items():
            print(f"ipe: note: {scene.name}: {name} ({source.uri}) {source.repaired}", file=sys.stderr)
    chosen = chosen_perception(args, args.perception)  # its options: evidence, request arguments, a recording
    # one request from the options (engine.request); its errors read as the options (main: as_spelled)
    request = build_request(query_parameters=given_query_parameters(args), **chosen.request_arguments,
                            **given_request_arguments(args))
    model, sim = request.model, request.settings
    if args.png is not None and len(scenes) != 1:
        raise ConfigError("--png", f"draws one scene, but {args.path} holds {len(scenes)}; choose one with --tower")
    chosen.refuse_many(scenes, args.path)
    scenes = _answerable(args, scenes, refused, request)
    collected: list[Prediction] = []
    if args.json:
        run_predictions(scenes, request, args.workers,
                        lambda p: (collected.append(p), print(prediction_json(p), flush=True)), args.scheduler,
                        chosen.evidence)
    else:
        k = 1 if all(is_deterministic(s, model) for s in scenes) else args.samples
        print(f"sigma = {model.sigma_m:g} m, phi = {','.join(f'{v:g}' for v in model.phi_m_s2)} m/s^2, mu = {args.mu}, "
              f"k = {k}, preset = {sim.name}, seed = {args.seed}" + chosen.heading(model))
        run_predictions(scenes, request, args.workers, collected.append, args.scheduler, chosen.evidence)
        print(format_table(collected))
        for line in describe(collected, args.perception):
            print(line)
    written = chosen.record(scenes[0], collected[0].perceived, model)
    if written is not None:
        print(f"wrote {written}", file=sys.stderr)
    if args.png is not None:
        from .viz.figure import draw_prediction

        draw_prediction(args.png, scenes[0], collected[0])
        print(f"wrote {args.png}", file=sys.stderr)
    return EXIT_BAD_INPUT if refused else 0  # the others answered; the status says not all could be


def _answerable(args, scenes: list, refused: list[RefusedScene], request) -> list:
    """The scenes that can be answered; the others refused (reported at once, before the predictions'
    minutes). A file's one scene refused is the command's error; none answerable, a SceneError."""
    unread = {r.index for r in refused}  # a scene's position in the file counts the unreadable ones too
    positions = {id(scene): i for scene, i in zip(scenes, (i for i in range(len(scenes) + len(unread))
                                                           if i not in unread))}
    answerable = []
    for scene in scenes:
        try:
            check_request(scene, request.query, model=request.model, settings=request.settings, budget_s=args.budget_s)
            answerable.append(scene)
        except ConfigError as exc:
            field = spelled(exc.field, "cli") + (f" ({scene.name})" if exc.field == "budget_s" else "")
            refused.append(RefusedScene(positions[id(scene)], scene.name, ConfigError(field, exc.problem)))
    if len(scenes) == 1 and not answerable and len(refused) == 1:
        raise refused[-1].error
    _report_refused(args, refused)
    if not answerable:
        raise SceneError(args.path, f"none of its {len(refused)} scenes can be answered (each refusal is reported)")
    return answerable


def _report_refused(args, refused: list[RefusedScene]) -> None:
    for refusal in refused:
        report = {"scene": refusal.name, "index": refusal.index, "error": str(refusal.error)}
        print(json.dumps(report) if args.json else f"ipe: refused scene {refusal.index} "
              f"({refusal.name or 'unnamed'}): {refusal.error}", file=sys.stdout if args.json else sys.stderr, flush=True)
