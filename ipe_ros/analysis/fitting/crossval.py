"""k-fold cross-validation by stimulus: on each fold's training stimuli the grid point and the
response mapping of the largest likelihood are chosen; the held-out stimuli score them.

Scores on the held-out stimuli: Pearson r of the mapped P(yes) with people's shares; the
log-likelihood of people's responses against a baseline that ignores the scene (the training
stimuli's mean share); accuracy (mapped P(yes) > 1/2) against the true outcome and against people's
majority. The same is scored for the reference point (the paper's parameters, its mapping fitted on
the same training stimuli), so a fold's gain is the fit's, not the mapping's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mapping import ResponseMapping, baseline_loglik, binomial_loglik, fit_mapping
from .responses import Responses


def folds(count: int, k: int, seed: int) -> list[np.ndarray]:
    """``k`` disjoint sets of stimulus indices covering ``range(count)``, shuffled by ``seed``."""
    order = np.random.default_rng(seed).permutation(count)
    return [np.sort(part) for part in np.array_split(order, k)]


@dataclass(frozen=True)
class Scores:
    r: float
    loglik: float
    accuracy_truth: float | None
    accuracy_majority: float


@dataclass(frozen=True)
class FoldResult:
    fold: int
    test: np.ndarray
    chosen: int  # grid index
    mapping: ResponseMapping
    fitted: Scores
    reference: Scores
    baseline_loglik: float
    p_yes: np.ndarray  # the fitted model's mapped P(yes) on the held-out stimuli
    reference_p_yes: np.ndarray


def pearson(a: np.ndarray, b: np.ndarray) -> float:
    if len(a) < 3 or np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])


def score(p_yes: np.ndarray, responses: Responses, rows: np.ndarray) -> Scores:
    share, n = responses.yes_share[rows], responses.responders[rows]
    says = p_yes > 0.5
    truth = None if responses.truth is None else float(np.mean(says == (responses.truth[rows] > 0.5)))
    return Scores(pearson(p_yes, share), binomial_loglik(p_yes, responses.yes_counts[rows], n), truth,
                  float(np.mean(says == (share > 0.5))))


def train(p_models: np.ndarray, responses: Responses, rows: np.ndarray,
          samples: int) -> tuple[np.ndarray, list[ResponseMapping]]:
    """Per grid point, the training log-likelihood with its best mapping, and those mappings."""
    yes, n = responses.yes_counts[rows], responses.responders[rows]
    lls, mappings = [], []
    for p_model in p_models:
        mapping, ll = fit_mapping(p_model[rows], yes, n, samples)
        lls.append(ll), mappings.append(mapping)
    return np.array(lls), mappings


def cross_validate(p_models: np.ndarray, responses: Responses, reference: int, k: int, seed: int,
                   samples: int) -> list[FoldResult]:
    """``p_models``: (grid points, stimuli) model probabilities of ``samples`` samples each;
    ``reference``: the grid index of the point the fit is held against."""
    out = []
    everyone = np.arange(p_models.shape[1])
    for f, test in enumerate(folds(p_models.shape[1], k, seed)):
        rows = np.setdiff1d(everyone, test)
        lls, mappings = train(p_models, responses, rows, samples)
        chosen = int(np.argmax(lls))
        p_yes = mappings[chosen].p_yes(p_models[chosen][test])
        reference_p_yes = mappings[reference].p_yes(p_models[reference][test])
        base = baseline_loglik(float(np.average(responses.yes_share[rows], weights=responses.responders[rows])),
                               responses.yes_counts[test], responses.responders[test])
        out.append(FoldResult(f, test, chosen, mappings[chosen], score(p_yes, responses, test),
                              score(reference_p_yes, responses, test), base, p_yes, reference_p_yes))
    return out


def pooled(results: list[FoldResult], responses: Responses, reference: bool = False) -> Scores:
    """The held-out predictions of every fold together (each stimulus predicted once, by the fold
    that did not train on it)."""
    count = sum(len(r.test) for r in results)
    p_yes = np.empty(count)
    for r in results:
        p_yes[r.test] = r.reference_p_yes if reference else r.p_yes
    return score(p_yes, responses, np.arange(count))
