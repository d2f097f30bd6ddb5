"""The self-check of an answer's samples as a plan (``montecarlo``): verification, refinement,
confirmation, coverage and escalation (the rules and the verdicts: ``fidelity``)."""

from __future__ import annotations

import numpy as np

from ..config import SimSettings
from .bias import bias_estimates, confirmation_samples, coverage_samples, undecided_bias_samples
from .fidelity import (ESCALATION_REASONS, FidelityReport, SelfCheck, contradicts, difference, merge, outcome_flags,
                       outcome_labels, suspect, unhealthy, verification_count)
from ..sampling.montecarlo import Plan
from ..results.outcome import SampleOutcome, energy_scale_of, rigid_reruns
from ..sampling.rollout import SampleTask


class _Comparison:
    """One answer's samples and the reference reruns gathered so far (``checked``: sample -> rerun)."""

    def __init__(self, tasks: list[SampleTask], outcomes: list[SampleOutcome], checked: dict[int, SampleOutcome],
                 check: SelfCheck, reference: SimSettings):
        self.tasks, self.outcomes, self.checked, self.check, self.reference = tasks, outcomes, checked, check, reference
        self.at_least = min(check.escalate_min_samples, len(tasks))
        #: every good sample's fast outcome flags (what the bias is estimated over)
        self.fast_flags = {i: outcome_flags(o) for i, o in enumerate(outcomes) if o.ok}
        self._biases: tuple[tuple[int, ...], list] = ((), [])  # the last compared samples' bias estimates

    def rerun(self, samples: list[int]) -> Plan:
        """These samples rerun at the reference (a round only when there are any)."""
        if samples:
            self.checked.update(zip(samples, (yield [self.tasks[i].at(self.reference) for i in samples])))

    def differences(self) -> dict[int, np.ndarray]:
        return {i: difference(self.outcomes[i], ref) for i, ref in self.checked.items()
                if ref.ok and self.outcomes[i].ok}

    def contradicted(self, compared: dict[int, np.ndarray]) -> bool:
        tolerance = self.check.bias_tolerance
        if tolerance is None:
            return contradicts(list(compared.values()), self.check.escalate_share, self.at_least)
        return any(b.escalates(tolerance, self.at_least, self.check.same_way) for b in self.biases(compared))

    def undecided(self, compared: dict[int, np.ndarray]) -> bool:
        """Some outcome's bias is neither credibly within the tolerance nor credibly beyond it, on
        the same-way differences that would escalate it if it were (``SelfCheck.when_undecided``)."""
        tolerance, counted = self.check.bias_tolerance, self.check.same_way
        return tolerance is not None and any(not b.within(tolerance) and not b.beyond(tolerance)
                                             and b.differing(counted) >= self.at_least
                                             for b in self.biases(compared))

    def biases(self, compared: dict[int, np.ndarray]) -> list:
        """``bias_estimates`` of these compared samples (a round asks twice: to decide, then to pick)."""
        key = tuple(sorted(compared))
        if key != self._biases[0]:
            self._biases = (key, bias_estimates(self.fast_flags, compared))
        return self._biases[1]

    def rigid_reruns(self) -> int:
        """Reference reruns whose multibody rollout ended unhealthy and was rerun in plain rigid bodies."""
        return rigid_reruns(self.checked.values())


def checking(tasks: list[SampleTask], outcomes: list[SampleOutcome], verified: dict[int, SampleOutcome],
             check: SelfCheck, reference: SimSettings, fast_name: str, validated: str = "",
             rerun: dict[int, SampleOutcome] | None = None) -> Plan:
    """The self-check of one answer's samples, as a plan (``montecarlo``): it yields the samples it
    wants rerun, at the reference, is sent their reruns, and returns the outcomes the answer uses and
    the report. ``tasks[i]`` made ``outcomes[i]`` at the fast settings ``fast_name``; ``verified[i]``:
    sample i already rerun at the reference. ``validated``: why the scene lies inside the validated
    envelope (``envelope.py``; ``check`` then verifies and covers nothing): the unhealthy rollouts are
    refined and what they show confirmed as anywhere; the verdict ``validated`` unless that escalates.
    ``rerun[i]``: sample i's rerun at the reference made in its own task because it ended unhealthy
    (``rollout.Refine``), so that refinement needs no round for it."""
    parts = [("samples", fast_name)]
    if not check.enabled:
        return outcomes, FidelityReport("unverified", settings=tuple(parts))
        yield  # a generator even when it returns at once
    known = {i: ref for i, ref in verified.items() if i < len(outcomes)}
    state = _Comparison(tasks, outcomes, {**{i: ref for i, ref in (rerun or {}).items() if i < len(outcomes)},
                                          **known}, check, reference)
    # 1. verification: the first samples with a fast outcome (a prediction's ran beside the fast
    # samples, in the first map; anytime sampling may have stopped before them)
    first = [i for i, o in enumerate(outcomes) if o.ok][:verification_count(check, len(outcomes))]
    yield from state.rerun([i for i in first if i not in state.checked])
    if known or first:
        parts.append(("verification", reference.name))
    # 2. refinement: the rollouts that ended unhealthy are rerun (a verified sample's rerun is at hand)
    reasons = {i: why for i, (task, outcome) in enumerate(zip(tasks, outcomes))
               if (why := unhealthy(outcome, energy_scale_of(task.scene), check)) is not None}
    yield from state.rerun([i for i in reasons if i not in state.checked])
    refined = {i: state.checked[i] for i in reasons if state.checked[i].ok}
    if refined:
        parts.append(("refined", reference.name))
    # the refined reruns alone moving some outcome by escalate_min_samples samples: that repair is
    # not small, and (chosen by how the fast rollouts ended) not unbiased; the reference answers
    repair = suspect([d for i, d in state.differences().items() if i in refined])
    # samples verified beyond the first ones (``fidelity.coverage_ahead``) were coverage's picks
    cover = check.cover_samples - len([i for i in verified if i >= verification_count(check, len(tasks))])
    yield from _confirm(state, repair, cover)
    compared = state.differences()
    disagreeing = [i for i, d in compared.items() if d.any()]
    common = dict(verified_samples=len(compared), disagreeing_samples=len(disagreeing),
                  refined_samples=len(refined), refined_reasons=tuple((i, reasons[i]) for i in sorted(refined)))
    # every sample already has its reference rerun and some differ: the reference's answer is at hand
    known = bool(disagreeing) and len(compared) == len(outcomes)
    # the rounds are spent and some bias is still open, on the differences that would escalate it
    # were it credibly beyond the tolerance: not verified (``SelfCheck.when_undecided``)
    open_bias = check.when_undecided == "escalate" and state.undecided(compared)
    because = tuple(reason for reason, held in zip(ESCALATION_REASONS, (
        state.contradicted(compared), open_bias, repair >= state.at_least, known)) if held)
    if not because:
        # a confirmation or a coverage rerun the budget cut off neither confirmed nor dismissed a bias
        unconfirmed = any(o.budget_stopped for o in state.checked.values())
        verdict = "verified" if first and all(i in compared for i in first) and not unconfirmed else "unverified"
        if validated:
            verdict = "validated" if not unconfirmed else "unverified"
        return merge(outcomes, refined), FidelityReport(verdict, settings=tuple(parts), validated=validated,
                                                        rigid_reruns=state.rigid_reruns(), **common)
    # 4. escalation: contradicted on this scene. First only the disputed strata (``disputed_strata``)
    # at the reference, where what the side kept fast shows could pass (``_credibly_within``, judged
    # before the rerun and again after it); else every sample, in one round
    parts.append(("escalation", reference.name))
    common["escalated_because"] = because
    if not known and check.bias_tolerance is not None:
        answered = yield from _escalate_disputed(state, compared, refined, parts, common)
        if answered is not None:
            return answered
    yield from state.rerun([i for i in range(len(outcomes)) if i not in state.checked and not outcomes[i].skipped])
    done = state.checked
    if any(o.budget_stopped for o in done.values()):
        return merge(outcomes, refined), FidelityReport("contradicted", settings=tuple(parts),
                                                        rigid_reruns=state.rigid_reruns(), **common)
    return merge(outcomes, done), FidelityReport("escalated", escalated_samples=len(done), settings=tuple(parts),
                                                 rigid_reruns=state.rigid_reruns(), **common)


def _escalate_disputed(state: "_Comparison", compared: dict[int, np.ndarray], refined: dict[int, SampleOutcome],
                       parts: list, common: dict) -> Plan:
    """The disputed strata alone rerun at the reference (``disputed_strata``), where what each side
    kept fast shows could pass (``_credibly_within``, judged before the rerun and again after it):
    the answer so made and its report, or None (then every sample is rerun)."""
    tasks, outcomes, check, reference = state.tasks, state.outcomes, state.check, state.reference
    strata = disputed_strata(state, compared)
    escalated = [j for j, _, _ in strata]
    disputed = sorted({i for _, _, members in strata for i in members})
    remaining = [i for i in range(len(outcomes)) if i not in state.checked and not outcomes[i].skipped]
    # the differences once the disputed samples are the reference's: none there, the rest as compared
    hoped = {**{i: d for i, d in compared.items() if i not in disputed},
             **{i: np.zeros_like(state.fast_flags[i]) for i in disputed}}
    if strata and len([i for i in disputed if i not in state.checked]) < len(remaining) and _credibly_within(
            state.fast_flags, hoped, escalated, check.bias_tolerance):
        yield from state.rerun([i for i in disputed if i not in state.checked])
        replaced = {**refined, **{i: state.checked[i] for i in disputed}}
        if not any(state.checked[i].budget_stopped for i in disputed):
            merged = merge(outcomes, replaced)
            after = _Comparison(tasks, merged, dict(state.checked), check, reference)
            if _credibly_within(after.fast_flags, after.differences(), escalated, check.bias_tolerance):
                labels = outcome_labels(next(o for o in outcomes if o.ok))
                return merged, FidelityReport(
                    "escalated", escalated_samples=len(disputed), settings=tuple(parts),
                    escalated_strata=tuple((labels[j] if j < len(labels) else f"outcome {j}", side, len(members))
                                           for j, side, members in strata),
                    rigid_reruns=state.rigid_reruns(), **common)
    return None


def _credibly_within(fast_flags: dict[int, np.ndarray], differences: dict[int, np.ndarray], escalated: list[int],
                     tolerance: float) -> bool:
    """Whether an answer whose disputed samples are the reference's (``differences``: none there) is
    credibly within ``tolerance`` of the reference's on every outcome that differs and on every one
    that ``escalated``: the side kept fast was compared without a difference, but chaos flips either
    way, and a side looked at in few samples could still hide flips that the rerun side no longer
    cancels (then every sample)."""
    return bool(differences) and all(b.within(tolerance) for b in bias_estimates(fast_flags, differences,
                                                                                  also=escalated))


def disputed_strata(state: _Comparison, compared: dict[int, np.ndarray]) -> list[tuple[int, str, list[int]]]:
    """Where the fast physics is disputed (the bias rule): per outcome whose bias escalates (or,
    escalated by refinement, every outcome some compared sample differs on), each fast side ("yes",
    "no") on which a compared sample differs, with every good sample on that side. A wrong fast
    physics can only show an outcome's bias on the side it says (``bias_estimates``): those samples
    rerun at the reference answer exactly as it would, and the other side, compared without a
    difference, keeps its fast outcomes where that is credible (``_credibly_within``).
    (outcome, side, samples) by outcome, "yes" first."""
    tolerance = state.check.bias_tolerance
    outcomes = [b.outcome for b in state.biases(compared)
                if b.escalates(tolerance, state.at_least, state.check.same_way)]
    if not outcomes:  # escalated by refinement: every outcome a compared sample differs on
        outcomes = sorted({int(j) for d in compared.values() for j in np.flatnonzero(d)})
    strata = []
    for j in outcomes:
        for side, name in ((1.0, "yes"), (0.0, "no")):
            if any(d[j] != 0 and state.fast_flags[i][j] == side for i, d in compared.items() if i in state.fast_flags):
                members = sorted(i for i, f in state.fast_flags.items() if f.shape[0] > j and f[j] == side)
                strata.append((j, name, members))
    return strata


def _confirm(state: _Comparison, repair: int, cover: int) -> Plan:
    """3. confirmation: every sample rerun so far is a paired comparison, refined ones included (a
    fast physics whose unhealthy rollouts topple what the reference's keep standing is wrong on this
    scene, and replacing only those would bias the answer), and a suspect difference is looked for
    again where it can show before it is believed; while nothing differs, one round looks where a bias
    could hide from the samples compared so far (coverage)."""
    check, outcomes = state.check, state.outcomes
    confirmations = 0
    while True:
        compared = state.differences()
        found = suspect(list(compared.values()))
        if repair >= state.at_least or state.contradicted(compared):
            return  # decided
        fast = {i: f for i, f in state.fast_flags.items() if i not in state.checked}
        if check.bias_tolerance is not None and any(d.any() for d in compared.values()):
            # some outcome differs: compare more where its bias is still undecided
            # past its rounds, "confirm" goes on while an undecided bias has the differences to escalate
            more = confirmations < check.confirm_rounds or (check.when_undecided == "confirm"
                                                            and state.undecided(compared))
            picked = [] if not more else undecided_bias_samples(
                state.fast_flags, list(fast), state.biases(compared), check.bias_tolerance,
                check.confirm_samples, state.at_least, check.same_way)
            confirmations += 1
        # a second confirmation round only while something is suspicious
        elif found and confirmations < check.confirm_rounds and not (confirmations and found < 2):
            picked = confirmation_samples(fast, compared, check.confirm_samples)
            confirmations += 1
        elif not found and cover > 0:
            looked = [outcome_flags(outcomes[i]) for i in compared]
            picked = coverage_samples(fast, looked, state.at_least, cover)
            cover = 0
        else:
            return
        if not picked:
            return
        yield from state.rerun(picked)
