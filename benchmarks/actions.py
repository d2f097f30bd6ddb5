"""What the robot questions cost (issue 32's targets), measured on this machine in one run.

    .venv/bin/python benchmarks/actions.py [--workers 2] [--out benchmarks/results/actions]

Each decision question is answered three times on the same seeds, interleaved: sequentially with the
self-check (the default: variants sampled in batches until decided, ``engine/sampling/decide.py``, then each
variant checked against the reference physics, ``engine/checking/fidelity.py``), sequentially without it, and
at fixed k without it (``sequential=False``); the decisions of the two unchecked runs are compared,
and the checked run's cost and escalations reported:
- the support graph of a 10-block paper tower at k = 16 per variant (target <= 1 s);
- "safe to remove?" for the top block at k = 48 (target <= 0.4 s);
- best place on a 20 x 20 cm region, 16 candidates, k = 16 (target <= 2 s), and at a robot's noise the
  same for a block of the tower's own kind (target <= 3 s; each candidate of both lies inside the validated envelope);
  these three at the paper's noise (sigma 4 cm), at which the tower falls by itself in most samples
  and the variants run only in the few where it stands, and at a robot's (``--robot-sigma``, 5 mm),
  at which it stands in most;
- the support graph of a column of 5-40 cubes at k = 8 (target for 40: <= 8 s);
- cost of one removal question vs the number of unrelated towers 10 m apart (1-8): objects an
  action cannot reach are left out of its rollouts, so it should cost about one tower.

Towers: the authors' stable 10-block towers from ../shared/data/battaglia2013/willitfall.csv (the
first one their ground truth keeps standing; generated paper-style towers without the data).
Each figure is the median of ``--repeats`` runs with a warm worker pool. DDS is not involved.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import os
import statistics
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from ipe_ros.engine import Box, Floor, ModelConfig, Scene, WorkerPool, preset  # noqa: E402
from ipe_ros.engine import Request
from ipe_ros.engine import actions as A  # noqa: E402
from ipe_ros.engine.config import DEFAULT_SIGMA_M  # noqa: E402
from ipe_ros.engine.sampling.decide import Ranking, SafeBelow, Supports, Tally  # noqa: E402
from ipe_ros.engine.checking.fidelity import DEFAULT_CHECK, reference_settings  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
I = (0.0, 0.0, 0.0, 1.0)


def stable_tower() -> Scene:
    from ipe_ros.analysis.paper_data import EXP1_DATASET, authors_outcomes, shared_data_dir
    from ipe_ros.engine.scene.files import scenes_from_tower_csv

    csv = shared_data_dir() / "willitfall.csv"
    if csv.exists():
        outcomes = authors_outcomes(EXP1_DATASET, shared_data_dir())
        for scene in scenes_from_tower_csv(csv):
            if outcomes.get(scene.name) is not None and outcomes[scene.name].stable:
                return scene
    from ipe_ros.engine.scene.generators import generate_towers

    return generate_towers(2013, 1)[0]


def column(n: int, size: float = 0.1) -> Scene:
    boxes = tuple(Box(name=f"c{i}", extents_m=(size,) * 3, position_m=(0.0, 0.0, size * (i + 0.5)), orientation_xyzw=I,
                      friction=0.6, restitution=0.0, mass_kg=1.0) for i in range(n))
    return Scene(name=f"column_{n}", objects=boxes, support=Floor(friction=0.6, restitution=0.0),
                 gravity_m_s2=(0.0, 0.0, -9.81))


def shelf(tower: Scene, copies: int, spacing_m: float = 10.0) -> Scene:
    objects = []
    for c in range(copies):
        for b in tower.objects:
            x, y, z = b.position_m
            objects.append(dataclasses.replace(b, name=f"t{c}_{b.name}", position_m=(x + c * spacing_m, y, z)))
    return dataclasses.replace(tower, name=f"shelf_{copies}", objects=tuple(objects))


def timed(fn, repeats: int):
    """(median seconds, the last result)."""
    walls, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        walls.append(time.perf_counter() - start)
    return statistics.median(walls), result


def _tallies(answers: A.Answers) -> dict[str, Tally]:
    """Each variant's standing-sample counts, as the rules read them."""
    out = {}
    for v in answers.variants:
        given = v.given_stands
        if v.label == "as_is" or given is None or not v.simulated:
            continue
        n = given.samples
        out[v.label] = Tally(n, round((given.any_fall_probability or 0.0) * n),
                             {name: round(p * n) for name, p in (given.object_fall_probability or {}).items()})
    return out


def _point(rule, tally: Tally):
    """The answer a fixed-k run acts on where its interval did not decide: the point estimates."""
    if tally.samples == 0:
        return None
    p = tally.any_falls / tally.samples
    if isinstance(rule, Supports):
        return (p < rule.safe_below, frozenset(n for n, c in tally.object_falls.items() if c / tally.samples >= rule.threshold))
    if isinstance(rule, SafeBelow):
        return p < rule.level
    return None  # ranking: compared by the candidate each run puts first


def compare(rule, sequential: A.Answers, fixed: A.Answers) -> dict:
    """Per variant: the sequential decision against the fixed-k run's (its full k through the same
    rule) where that decided, and the point-estimate answers where it did not."""
    fixed_tallies, seq_tallies = _tallies(fixed), _tallies(sequential)
    fixed_decided = rule.decide(fixed_tallies, set(fixed_tallies))
    seq_decisions = {v.label: v.decision for v in sequential.variants if v.label in seq_tallies}
    decided = [label for label in fixed_decided if label in seq_decisions]
    same = sum(seq_decisions[label] == fixed_decided[label] for label in decided)
    undecided = [label for label in fixed_tallies if label not in fixed_decided]
    differ = sum(_point(rule, seq_tallies[label]) != _point(rule, fixed_tallies[label]) for label in undecided
                 if _point(rule, fixed_tallies[label]) is not None)
    drawn = [v.samples_drawn for v in sequential.variants if v.samples_drawn is not None]
    return {"fixed_decided": len(decided), "same_decision": same, "fixed_undecided": len(undecided),
            "point_answer_differs": differ, "mean_samples_drawn": statistics.mean(drawn) if drawn else None}


def _reference_rollouts(answers: A.Answers) -> int:
    """The rollouts a checked answer ran at the reference: each variant's compared (and refined)
    samples, or, escalated, every sample it reran."""
    total = 0
    for v in answers.variants:
        report = v.self_check or {}
        total += report.get("escalated_samples", 0) if v.fidelity == "escalated" else \
            report.get("verified_samples", 0) + report.get("refined_samples", 0)
    return total


def _fast_rollouts(answers: A.Answers) -> int:
    return sum(v.samples for v in answers.variants if v.simulated)


def check_floor(run, seq_s: float, seq_answers: A.Answers, checked_answers: A.Answers, workers: int, first) -> dict:
    """What any check that compares one sample of each variant it checks (those not validated) with
    the reference must add to the unchecked answer: that many reference rollouts, priced by the
    same question answered at the reference (unchecked, once, the same seeds)."""
    checked = [v for v in checked_answers.variants if v.fidelity not in (None, "validated", "unverified")]
    counts = {"fast_rollouts": _fast_rollouts(seq_answers), "reference_rollouts": _reference_rollouts(checked_answers),
              "compared_variants": len(checked)}
    if not checked:
        return {**counts, "floor_s": seq_s}
    reference_s, reference = timed(lambda: run(True, None, reference_settings()), 1)
    reference = reference if first is None else reference[1]
    per_reference_s = reference_s * workers / max(1, _fast_rollouts(reference))
    per_fast_s = seq_s * workers / max(1, counts["fast_rollouts"])
    return {**counts, "reference_s": reference_s, "reference_over_fast_per_rollout": per_reference_s / per_fast_s,
            "floor_s": seq_s + len(checked) * per_reference_s / workers}


def both(name: str, target_s: float | None, run, rule, repeats: int, first=None, workers: int = 2) -> dict:
    """One question answered sequentially with and without the self-check and at fixed k without
    it, on the same seeds, interleaved; and the check's floor (``check_floor``).
    ``run(sequential, check, physics=settings)``."""
    checked_s, checked = timed(lambda: run(True, DEFAULT_CHECK), repeats)
    seq_s, seq = timed(lambda: run(True, None), repeats)
    fixed_s, fixed = timed(lambda: run(False, None), repeats)
    seq_answers, fixed_answers, checked_answers = (seq, fixed, checked) if first is None else \
        (seq[1], fixed[1], checked[1])
    floor = check_floor(run, seq_s, seq_answers, checked_answers, workers, first)
    verdicts = [v.fidelity for v in checked_answers.variants if v.fidelity is not None]
    alone = fixed_answers.alone
    row = {"question": name, "target_s": target_s, "checked_s": checked_s, "sequential_s": seq_s, "fixed_s": fixed_s,
           "checked_variants": len(verdicts), "escalated_variants": verdicts.count("escalated"),
           "validated_variants": verdicts.count("validated"),
           # the variants are simulated only in the samples where the scene as it is stands
           "as_is_standing": None if alone is None else alone.samples_standing,
           "samples": fixed_answers.samples_requested, **compare(rule, seq_answers, fixed_answers), **floor}
    if first is not None:  # a ranking: the candidate each run puts first, and its fixed-k P
        chosen, best = first(seq), first(fixed)
        row["same_first_choice"] = chosen == best
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=str(REPO / "benchmarks/results/actions"))
    parser.add_argument("--heights", default="5,10,20,40")
    parser.add_argument("--shelves", default="1,2,4,8")
    parser.add_argument("--robot-sigma", type=float, default=0.005,
                        help="the second noise level the tower's questions are asked at, m (0: none)")
    args = parser.parse_args()
    settings = preset("default")
    tower = stable_tower()
    top_block = max(tower.dynamic_objects, key=lambda b: b.position_m[2])
    top = top_block.name
    rows = []
    with WorkerPool(args.workers) as pool:
        pool.warm()
        kw = dict(map_fn=pool.map)

        def model(k, sigma=DEFAULT_SIGMA_M):
            return ModelConfig(sigma_m=sigma, samples=k)

        supports = Supports(A.DEFAULT_SUPPORT_THRESHOLD, A.DEFAULT_SAFE_BELOW)
        ask_both = functools.partial(both, workers=args.workers)
        block = Box(name="new", extents_m=(0.2, 0.2, 0.2), position_m=(0.0, 0.0, 0.0), orientation_xyzw=I,
                    friction=0.6, restitution=0.0, mass_kg=1.0)
        own_kind = dataclasses.replace(top_block, name="new", position_m=(0.0, 0.0, 0.0))
        centre = top_block.position_m
        region = A.Region((centre[0] - 0.1, centre[0] + 0.1), (centre[1] - 0.1, centre[1] + 0.1))
        # the paper's perceptual noise, at which this tower falls by itself in most samples (so that its
        # variants run in few), and a robot's (a few mm), at which it stands in most
        for sigma in (DEFAULT_SIGMA_M, args.robot_sigma) if args.robot_sigma else (DEFAULT_SIGMA_M,):
            noise = f"sigma {sigma * 1000:g} mm"
            rows.append(ask_both(f"support graph, {tower.name} (10 blocks), k = 16 per variant, {noise}", 1.0,
                             lambda seq, check, physics=settings, sigma=sigma: A.support_graph(
                                 tower, model(16, sigma), physics, sequential=seq, check=check, **kw).answers,
                             supports, args.repeats))
            rows.append(ask_both(f"safe to remove the top block ({top}), k = 48, {noise}", 0.4,
                             lambda seq, check, physics=settings, sigma=sigma: A.remove(
                                 tower, [top], model(48, sigma), physics, safe_below=A.DEFAULT_SAFE_BELOW,
                                 sequential=seq, check=check, **kw),
                             SafeBelow(A.DEFAULT_SAFE_BELOW), args.repeats))
            rows.append(ask_both(f"best place on the tower's top, 20 x 20 cm, 16 candidates, k = 16, {noise}", 2.0,
                             lambda seq, check, physics=settings, sigma=sigma: A.best_place(
                                 tower, block, region, model(16, sigma), physics, candidates=16, sequential=seq,
                                 check=check, **kw),
                             Ranking(), args.repeats, first=lambda result: result[0][0][0].position_m))
            if sigma != DEFAULT_SIGMA_M:
                # a block of the tower's own kind: each candidate lowered onto the top is boxes at rest,
                # inside the validated envelope (so is the 1 kg cube, 4x lighter than the blocks it rests on)
                rows.append(ask_both(f"best place of a block like the tower's own, 16 candidates, k = 16, {noise}", 3.0,
                                 lambda seq, check, physics=settings, sigma=sigma: A.best_place(
                                     tower, own_kind, region, model(16, sigma), physics, candidates=16,
                                     sequential=seq, check=check, **kw),
                                 Ranking(), args.repeats, first=lambda result: result[0][0][0].position_m))
        for n in map(int, args.heights.split(",")):
            scene = column(n)
            rows.append(ask_both(f"support graph, column of {n} 10 cm cubes, k = 8 per variant (one run)",
                             8.0 if n == 40 else None,
                             lambda seq, check, physics=settings: A.support_graph(
                                 scene, ModelConfig(sigma_m=0.005, samples=8), physics, sequential=seq, check=check,
                                 **kw).answers, supports, 1))
        shelves = []
        for copies in map(int, args.shelves.split(",")):
            scene = shelf(tower, copies)
            seconds, _ = timed(lambda: A.ask(scene, [A.Remove((f"t0_{tower.dynamic_objects[0].name}",))],
                                             Request(model=model(16), settings=settings, query=A.question_spec(),
                                                     check=None, budget_s=None)), args.repeats)
            shelves.append({"towers": copies, "seconds": seconds})
    report = {"date": time.strftime("%Y-%m-%d"), "workers": args.workers, "tower": tower.name, "questions": rows,
              "unrelated_towers": shelves}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "actions.json").write_text(json.dumps(report, indent=1) + "\n")
    lines = [f"# Robot questions: cost ({report['date']}, {args.workers} workers, `default`)", "",
             f"`.venv/bin/python benchmarks/actions.py`; medians of {args.repeats} runs with a warm pool (columns: one "
             "run), sequential and fixed-k interleaved on the same seeds. Decisions: where the fixed-k run's own "
             "interval decided a variant, is the sequential decision the same; where it did not, how often the "
             "point-estimate answers (edges, safe) differ. The variants are simulated only in the samples where the "
             "scene as it is stands (column 'stands').", "",
             "| question | stands | self-checked s (escalated, validated variants) | sequential s | fixed-k s | target s | decided at "
             "fixed k: same | undecided: answers differ | mean samples drawn |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        extra = "" if "same_first_choice" not in r else f"; first choice {'same' if r['same_first_choice'] else 'differs'}"
        stands = "-" if r["as_is_standing"] is None else f"{r['as_is_standing']} of {r['samples']}"
        lines.append(f"| {r['question']} | {stands} | {r['checked_s']:.2f} ({r['escalated_variants']}, "
                     f"{r.get('validated_variants', 0)} of {r['checked_variants']}) | "
                     f"{r['sequential_s']:.2f} | {r['fixed_s']:.2f} | "
                     f"{'-' if r['target_s'] is None else format(r['target_s'], 'g')} | "
                     f"{r['same_decision']} of {r['fixed_decided']} | {r['point_answer_differs']} of "
                     f"{r['fixed_undecided']}{extra} | "
                     f"{'-' if r['mean_samples_drawn'] is None else format(r['mean_samples_drawn'], '.1f')} |")
    lines += ["", "The check's floor: a check that compares at least one sample of each variant it does not validate "
              "adds that many reference rollouts to the unchecked (sequential) answer, each priced by the same "
              "question answered at the reference (unchecked, once): the least the checked answer can cost with "
              "these physics, escalating nothing (an estimate: reference rollouts that run beside fast ones are not "
              "credited). Rollouts: the fast answer's, and the checked answer's at the reference.", "",
              "| question | fast rollouts | reference rollouts (checked) | variants compared | reference / fast, "
              "per rollout | floor s | self-checked s | sequential s |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = r.get("reference_over_fast_per_rollout")
        lines.append(f"| {r['question']} | {r['fast_rollouts']} | {r['reference_rollouts']} | {r['compared_variants']} | "
                     f"{'-' if ratio is None else format(ratio, '.1f') + 'x'} | {r['floor_s']:.2f} | "
                     f"{r['checked_s']:.2f} | {r['sequential_s']:.2f} |")
    lines += ["", "One removal (k = 16) in a scene of N separate 10-block towers 10 m apart (a 3.2 m tower reaches 7.4 m: `actions.reach_m`):", "",
              "| towers | s |", "|---|---|"] + [f"| {r['towers']} | {r['seconds']:.2f} |" for r in shelves]
    (out / "actions.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
