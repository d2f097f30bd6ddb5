"""The inference's sampler: adaptive multiple importance sampling (AMIS; Cornuet et al. 2012), tempered.

Why this method: every likelihood evaluation is a rollout (milliseconds to a second), and the worker
pool runs a round of them at once. MCMC spends one rollout per sequential step and discards its
burn-in; SMC's move steps are MCMC too. AMIS draws a whole round from its current proposal, keeps
every rollout it ever ran (each weighed against the mixture of all proposals so far: the
"deterministic mixture" weights, which stay valid as the proposal adapts), and is anytime: after any
round its weighted particles are an answer, and their effective sample size says how good.

Adaptation is tempered: the next proposal is fitted to the weights with the likelihood raised to
the largest power beta <= 1 that keeps an effective size of ``adapt_fraction`` of a round (adaptive
tempering, as SMC's), so a sharp likelihood is approached over rounds (each zooming in on the best
fifth, as the cross-entropy method does) instead of collapsing onto the luckiest first-round
candidate. Each round's proposal is a Gaussian in the priors' unbounded coordinates
(inflated), mixed with the prior itself (``defensive_fraction``), so no region the prior allows is
ever given zero proposal density. Every draw comes from candidate i's own ``SeedSequence`` child:
the answer never depends on worker count or scheduling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ..sampling.montecarlo import Plan, child_seeds


@dataclass(frozen=True)
class AmisSettings:
    particles_per_round: int = 32
    max_rounds: int = 12
    #: stop once the untempered weights' effective sample size reaches this
    target_ess: float = 60.0
    #: the answer's weights keep at least this effective size: where the full likelihood leaves
    #: fewer (a chaotic scene, too few rollouts), it is raised to the power that keeps this many
    #: (a coarsened posterior, Miller & Dunson 2019), and the answer says so; never one lucky rollout
    min_ess: float = 20.0
    defensive_fraction: float = 0.1
    #: the next proposal is fitted to tempered weights whose effective size is this share of a round
    adapt_fraction: float = 0.2
    #: the fitted Gaussian's SDs are widened by this factor (proposals wider than the target are safe)
    spread: float = 1.5


@dataclass(frozen=True)
class AmisResult:
    coordinates: np.ndarray  # (N, d) every candidate run, in the priors' coordinates
    log_likelihoods: np.ndarray  # (N,) -inf for a failed rollout; NaN for one cut off by the budget
    log_weights: np.ndarray  # (N,) normalised, -inf where not usable
    outcomes: list
    rounds: int
    ess: float
    stopped_by: str  # "ess", "rounds" or "budget"
    likelihood_power: float = 1.0  # below 1: the likelihood coarsened to keep ``min_ess``

    @property
    def weights(self) -> np.ndarray:
        return np.exp(self.log_weights)


def effective_size(log_weights: np.ndarray) -> float:
    finite = log_weights[np.isfinite(log_weights)]
    if not len(finite):
        return 0.0
    w = np.exp(finite - finite.max())
    return float(w.sum() ** 2 / (w * w).sum())


def _normalised(log_weights: np.ndarray) -> np.ndarray:
    finite = np.isfinite(log_weights)
    if not finite.any():
        return log_weights
    top = log_weights[finite].max()
    return log_weights - (top + math.log(np.exp(log_weights[finite] - top).sum()))


@dataclass(frozen=True)
class _Gaussian:
    mean: np.ndarray
    chol: np.ndarray

    def log_density(self, z: np.ndarray) -> np.ndarray:
        solved = np.linalg.solve(self.chol, (z - self.mean).T).T
        log_det = 2 * np.log(np.diag(self.chol)).sum()
        return -0.5 * (np.sum(solved * solved, axis=1) + log_det + z.shape[1] * math.log(2 * math.pi))

    def draw(self, rng: np.random.Generator) -> np.ndarray:
        return self.mean + self.chol @ rng.standard_normal(len(self.mean))


def amis(priors: Sequence, make_task: Callable[[int, np.ndarray], object],
         read: Callable[[object], float | None], seed: int, settings: AmisSettings = AmisSettings()) -> Plan:
    """The plan: yields rounds of ``make_task(i, z)``, reads each outcome's log-likelihood with
    ``read`` (None: cut off by the budget; -inf: the rollout failed), returns an ``AmisResult``."""
    d, n = len(priors), settings.particles_per_round
    seeds = child_seeds(seed, n * settings.max_rounds)
    coordinates = np.empty((0, d))
    log_likelihoods = np.empty(0)
    outcomes: list = []
    proposals: list = [None]  # None: the prior itself (the first round)
    stopped_by = "rounds"

    def log_prior(z):
        return sum(p.log_density_z(z[:, j]) for j, p in enumerate(priors))

    def log_proposal(z, proposal):
        if proposal is None:
            return log_prior(z)
        return np.logaddexp(math.log1p(-settings.defensive_fraction) + proposal.log_density(z),
                            math.log(settings.defensive_fraction) + log_prior(z))

    def weights(beta):
        """Log weights with the likelihood raised to ``beta``; the prior and the proposals' mixture at
        the candidates are made once a round (``densities``), not at every tempering trial."""
        prior, mixture, usable = densities
        out = np.full(len(log_likelihoods), -np.inf)
        out[usable] = prior + beta * log_likelihoods[usable] - mixture
        return out

    for r in range(settings.max_rounds):
        proposal = proposals[-1]
        drawn = []
        for i in range(r * n, (r + 1) * n):
            rng = np.random.default_rng(seeds[i])
            if proposal is None or rng.random() < settings.defensive_fraction:
                drawn.append(np.array([p.z_from_uniform(rng.random()) for p in priors]))
            else:
                drawn.append(proposal.draw(rng))
        drawn = np.array(drawn, float).reshape(n, d)
        round_outcomes = yield [make_task(r * n + j, drawn[j]) for j in range(n)]
        read_values = [read(o) for o in round_outcomes]
        outcomes.extend(round_outcomes)
        coordinates = np.vstack([coordinates, drawn])
        log_likelihoods = np.concatenate([log_likelihoods,
                                          [np.nan if v is None else v for v in read_values]])
        densities = _densities(coordinates, log_likelihoods, log_prior, log_proposal, proposals)
        if any(v is None for v in read_values):
            stopped_by = "budget"
            break
        final = weights(1.0)
        if effective_size(final) >= settings.target_ess:
            stopped_by = "ess"
            break
        if r + 1 == settings.max_rounds:
            break
        proposals.append(_fitted(coordinates, weights(_temperature(weights, settings.adapt_fraction * n)),
                                      settings.spread))
    power = _temperature(weights, min(settings.min_ess, np.isfinite(log_likelihoods).sum() / 2))
    final = weights(power)
    return AmisResult(coordinates, log_likelihoods, _normalised(final), outcomes, len(proposals), effective_size(final),
                      stopped_by, power)


def _densities(coordinates, log_likelihoods, log_prior, log_proposal, proposals) -> tuple:
    """(the prior's log density, the deterministic mixture of every proposal so far, both at the
    usable candidates; which candidates are usable: a finite log-likelihood)."""
    mixture = np.logaddexp.reduce(np.stack([log_proposal(coordinates, q) for q in proposals]), axis=0) \
        - math.log(len(proposals))
    usable = np.isfinite(log_likelihoods)
    return log_prior(coordinates[usable]), mixture[usable], usable


def _temperature(weights: Callable[[float], np.ndarray], keep: float) -> float:
    """The largest beta <= 1 whose weights keep an effective size of at least ``keep``."""
    if effective_size(weights(1.0)) >= keep:
        return 1.0
    low, high = 0.0, 1.0
    for _ in range(30):
        mid = (low + high) / 2
        if effective_size(weights(mid)) >= keep:
            low = mid
        else:
            high = mid
    return low


def _fitted(coordinates: np.ndarray, log_weights: np.ndarray, spread: float) -> _Gaussian:
    usable = np.isfinite(log_weights)
    z, w = coordinates[usable], np.exp(_normalised(log_weights[usable]))
    mean = w @ z
    centred = z - mean
    cov = (centred * w[:, None]).T @ centred
    cov = spread ** 2 * cov + 1e-6 * np.eye(z.shape[1])
    return _Gaussian(mean, np.linalg.cholesky(cov))


def grid(priors: Sequence, make_task: Callable[[int, np.ndarray], object],
         read: Callable[[object], float | None], points: int) -> Plan:
    """A plain grid, the baseline AMIS is measured against (benchmarks/inference.py): ``points`` per
    unknown at the midpoints of equal prior mass (each point its prior's share), one round."""
    u = (np.arange(points) + 0.5) / points
    axes = [np.array([p.z_from_uniform(float(x)) for x in u]) for p in priors]
    coordinates = np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1)
    outcomes = yield [make_task(i, z) for i, z in enumerate(coordinates)]
    values = [read(o) for o in outcomes]
    log_likelihoods = np.array([np.nan if v is None else v for v in values], float)
    log_weights = np.where(np.isfinite(log_likelihoods), log_likelihoods, -np.inf)
    stopped_by = "budget" if any(v is None for v in values) else "rounds"
    return AmisResult(coordinates, log_likelihoods, _normalised(log_weights), list(outcomes), 1,
                      effective_size(log_weights), stopped_by)
