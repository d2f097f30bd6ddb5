"""From the model's probability to people's: P(yes) = lapse / 2 + (1 - lapse) * logistic(intercept +
slope * (p - 1/2)), fitted by the binomial likelihood of the responses.

The logistic lets people be more or less decisive than the model's probability (slope) and lean to
yes or no (intercept); the lapse rate is the share answering at random whatever they saw (at most
1/2), so one surprising stimulus cannot drive the slope. The slope is kept >= 0: a model whose
P(yes) falls as people's rises is a bad model, not a mapping to fit.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.special import expit, gammaln

MAX_LAPSE = 0.5
MAX_SLOPE = 100.0
_STARTS = ((0.0, 4.0, 0.05), (0.0, 12.0, 0.1), (0.0, 1.0, 0.01))


@dataclass(frozen=True)
class ResponseMapping:
    intercept: float = 0.0
    slope: float = 4.0
    lapse: float = 0.0

    def p_yes(self, p_model: np.ndarray) -> np.ndarray:
        return self.lapse / 2 + (1 - self.lapse) * expit(self.intercept + self.slope * (np.asarray(p_model) - 0.5))

    def to_dict(self) -> dict:
        return asdict(self)


def binomial_loglik(p_yes: np.ndarray, yes: np.ndarray, n: np.ndarray) -> float:
    """The log-likelihood of ``yes`` of ``n`` saying yes at ``p_yes`` each (with the binomial
    coefficients, so that models and baselines compare on one scale)."""
    p = np.clip(p_yes, 1e-12, 1 - 1e-12)
    return float(np.sum(gammaln(n + 1) - gammaln(yes + 1) - gammaln(n - yes + 1)
                        + yes * np.log(p) + (n - yes) * np.log1p(-p)))


def fit_mapping(p_model: np.ndarray, yes: np.ndarray, n: np.ndarray) -> tuple[ResponseMapping, float]:
    """The mapping of the largest likelihood, and that log-likelihood (a few starts; L-BFGS-B)."""
    p_model, yes, n = (np.asarray(a, float) for a in (p_model, yes, n))

    def loss(theta):
        return -binomial_loglik(ResponseMapping(*theta).p_yes(p_model), yes, n)

    best = None
    for start in _STARTS:
        found = minimize(loss, start, method="L-BFGS-B",
                         bounds=((-20.0, 20.0), (0.0, MAX_SLOPE), (0.0, MAX_LAPSE)))
        if best is None or found.fun < best.fun:
            best = found
    mapping = ResponseMapping(*(float(v) for v in best.x))
    return mapping, -float(best.fun)


def baseline_loglik(train_share: float, yes: np.ndarray, n: np.ndarray) -> float:
    """A model that ignores the scene: every stimulus gets the training stimuli's mean share."""
    return binomial_loglik(np.full(len(yes), train_share), yes, n)
