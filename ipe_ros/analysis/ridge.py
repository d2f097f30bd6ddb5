"""Cross-validated ridge regression from features to a target (paper SI "Model-Free Accounts").

The penalty is chosen by an inner k-fold cross-validation inside each outer training fold, and the
reported predictions are the outer folds' held-out ones, so the correlation they give is honest
(the paper selected the penalty "through a cross-validated fitting procedure"). Features are
standardised with the training fold's mean and spread. Plain numpy: the closed form
(X'X + alpha I)^-1 X'y on six to fourteen columns needs nothing more.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEFAULT_ALPHAS = tuple(float(a) for a in np.logspace(-3, 3, 13))


@dataclass(frozen=True)
class RidgeFit:
    """alpha: the penalty chosen on all data (for ``coefficients``). held_out: out-of-fold predictions
    per stimulus. coefficients: on standardised features, fitted to all data with ``alpha``."""

    alpha: float
    coefficients: np.ndarray
    intercept: float
    held_out: np.ndarray
    alphas_per_fold: tuple[float, ...]


def _fit(x: np.ndarray, y: np.ndarray, alpha: float) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    mean, scale = x.mean(axis=0), x.std(axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    z = (x - mean) / scale
    coef = np.linalg.solve(z.T @ z + alpha * np.eye(z.shape[1]), z.T @ (y - y.mean()))
    return coef, float(y.mean()), mean, scale


def _predict(fit, x: np.ndarray) -> np.ndarray:
    coef, intercept, mean, scale = fit
    return intercept + ((x - mean) / scale) @ coef


def _folds(n: int, k: int, rng: np.random.Generator) -> list[np.ndarray]:
    return np.array_split(rng.permutation(n), min(k, n))


def _choose_alpha(x: np.ndarray, y: np.ndarray, alphas, k: int, rng: np.random.Generator) -> float:
    folds = _folds(len(y), k, rng)
    errors = []
    for alpha in alphas:
        sq = 0.0
        for test in folds:
            train = np.setdiff1d(np.arange(len(y)), test)
            sq += float(((_predict(_fit(x[train], y[train], alpha), x[test]) - y[test]) ** 2).sum())
        errors.append(sq)
    return float(alphas[int(np.argmin(errors))])


def cross_validated_ridge(features: np.ndarray, target: np.ndarray, *, rng: np.random.Generator,
                          alphas=DEFAULT_ALPHAS, outer_folds: int = 5, inner_folds: int = 5) -> RidgeFit:
    """Nested cross-validation; ``features`` is (stimuli, features), ``target`` (stimuli,)."""
    x, y = np.asarray(features, float), np.asarray(target, float)
    if x.ndim != 2 or len(x) != len(y):
        raise ValueError(f"features: must be (stimuli, features) matching target's {len(y)} stimuli, got {x.shape}")
    if len(y) < 2 * outer_folds:
        raise ValueError(f"target: need at least {2 * outer_folds} stimuli for {outer_folds}-fold cross-validation")
    finite = np.all(np.isfinite(x), axis=0)
    x = x[:, finite]  # a feature undefined somewhere (e.g. no open edge) cannot be used
    held_out = np.empty(len(y))
    chosen = []
    for test in _folds(len(y), outer_folds, rng):
        train = np.setdiff1d(np.arange(len(y)), test)
        alpha = _choose_alpha(x[train], y[train], alphas, inner_folds, rng)
        chosen.append(alpha)
        held_out[test] = _predict(_fit(x[train], y[train], alpha), x[test])
    alpha = _choose_alpha(x, y, alphas, inner_folds, rng)
    coef, intercept, _, _ = _fit(x, y, alpha)
    full = np.full(len(finite), np.nan)
    full[finite] = coef
    return RidgeFit(alpha=alpha, coefficients=full, intercept=intercept, held_out=held_out,
                    alphas_per_fold=tuple(chosen))
