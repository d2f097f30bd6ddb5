"""The self-check of an answer's samples as a plan (``montecarlo``): verification, refinement,
confirmation, coverage and escalation (the rules and the verdicts: ``fidelity``)."""

from __future__ import annotations

import numpy as np

from ..config import SimSettings
from .fidelity import (FidelityReport, SelfCheck, confirmation_samples, contradicts, coverage_samples, difference,
                       merge, outcome_flags, scale_of, suspect, unhealthy, verification_count)
from ..sampling.montecarlo import Plan
from ..sampling.outcome import SampleOutcome
from ..sampling.rollout import SampleTask


def checking(tasks: list[SampleTask], outcomes: list[SampleOutcome], verified: dict[int, SampleOutcome],
             check: SelfCheck, reference: SimSettings, fast_name: str) -> Plan:
    """The self-check of one answer's samples, as a plan (``montecarlo``): it yields the samples it
    wants rerun, at the reference, is sent their reruns, and returns the outcomes the answer uses and
    the report. ``tasks[i]`` made ``outcomes[i]`` at the fast settings ``fast_name``; ``verified[i]``:
    sample i already rerun at the reference."""
    parts = [("samples", fast_name)]
    if not check.enabled:
        return outcomes, FidelityReport("unverified", settings=tuple(parts))
        yield  # a generator even when it returns at once

    def rerun_at(samples: list[int]) -> list[SampleTask]:
        return [tasks[i].at(reference) for i in samples]

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
        checked.update(zip(missing, (yield rerun_at(missing))))
    if checked:
        parts.append(("verification", reference.name))
    # 2. refinement: the rollouts that ended unhealthy are rerun (a verified sample's rerun is at hand)
    reasons = {i: why for i, (task, outcome) in enumerate(zip(tasks, outcomes))
               if (why := unhealthy(outcome, scale_of(task.scene), check)) is not None}
    rerun = [i for i in reasons if i not in checked]
    if rerun:
        checked.update(zip(rerun, (yield rerun_at(rerun))))
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
        checked.update(zip(picked, (yield rerun_at(picked))))
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
        done.update(zip(rest, (yield rerun_at(rest))))
    parts.append(("escalation", reference.name))
    if any(o.budget_stopped for o in done.values()):
        return merge(outcomes, refined), FidelityReport("contradicted", settings=tuple(parts), **common)
    return merge(outcomes, done), FidelityReport("escalated", escalated_samples=len(done), settings=tuple(parts),
                                                 **common)
