"""Metropolis-Hastings over the blocks' horizontal positions, given blurred images (SI "Bayesian
Vision System"): uniform prior, the image likelihood, single-block Gaussian moves.

The chain records one sample per block update; updates come in scans of as many updates as there
are dynamic bodies, the body of each update drawn uniformly with replacement (the SI's "order of
block updates was chosen uniformly with replacement, independently per scan"). It starts at the
state the images were made from and its first ``burn_in`` samples are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import PinholeCamera
from .likelihood import VisionSettings, blur_matrices, blur, log_likelihood
from .metropolis import run_metropolis, thinned_index
from .render import BACKGROUND_GREY, EMPTY, Patch, SceneMesh, body_patch, render


@dataclass(frozen=True)
class Chain:
    """A chain after burn-in.

    positions_m: (samples, dynamic bodies, 3) states (heights never change).
    log_likelihood: (samples,) of each state. acceptance_rate: over all proposals, burn-in included.
    accepted: every proposal's outcome, burn-in included (the acceptance trace).
    """

    positions_m: np.ndarray
    log_likelihood: np.ndarray
    acceptance_rate: float
    proposals: int
    accepted: np.ndarray | None = None  # (proposals,) whether each proposal was taken, burn-in included

    def coordinate_ess(self) -> np.ndarray:
        """ESS of every body's x and y (Geyer's initial positive sequence)."""
        values = self.positions_m[:, :, :2].reshape(len(self.positions_m), -1)
        return np.array([effective_sample_size(values[:, j]) for j in range(values.shape[1])])

    @property
    def effective_sample_size(self) -> float:
        """The median ESS over the bodies' coordinates. Not the minimum: a body no view constrains
        wanders without bound under the uniform prior, and its ESS says that, not how well the
        chain mixes (``coordinate_ess`` gives every coordinate's)."""
        return float(np.median(self.coordinate_ess()))

    def thinned(self, k: int) -> np.ndarray:
        """k states spread evenly over the chain (k <= samples)."""
        return self.positions_m[thinned_index(len(self.positions_m), k)]


def effective_sample_size(x: np.ndarray) -> float:
    """ESS of one chain: n / (1 + 2 sum of autocorrelations), summed in pairs while the pair sums stay
    positive (Geyer 1992). A constant chain has ESS 1: it says one thing."""
    x = np.asarray(x, float)
    n = len(x)
    centred = x - x.mean()
    variance = float(centred @ centred) / n
    if n < 4 or variance == 0:
        return 1.0
    spectrum = np.fft.rfft(centred, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n] / (n * variance)
    total, t = 0.0, 1
    while t + 1 < n:
        pair = acf[t] + acf[t + 1]
        if pair <= 0:
            break
        total += pair
        t += 2
    return float(min(n, n / (1 + 2 * total)))


class ImageModel:
    """The observed (blurred) images, and the rendered images of the chain's current state.

    A proposal moves one body, so only its pixels change: every body keeps its own depth layer per
    view, a proposal re-rasterises the moved body and re-composites the pixels it covered before or
    covers now, and, the blur being linear, adds the blurred change to the blurred image. The result
    equals a full render and blur of the proposed state (``tests/test_vision.py``)."""

    def __init__(self, mesh: SceneMesh, cameras: tuple[PinholeCamera, ...], observed: np.ndarray, settings: VisionSettings):
        self.mesh, self.cameras, self.settings = mesh, cameras, settings
        self.blur_px = settings.blur_at_resolution_px
        self.sd = settings.sd_at_resolution_grey
        self.observed_blurred = blur(np.asarray(observed, float), self.blur_px)
        self._k, self._k_t = blur_matrices(settings.resolution_px, float(self.blur_px))

    def log_likelihood(self, positions_m: np.ndarray) -> float:
        """From scratch: render every view, blur, compare."""
        rendered = np.stack([render(self.mesh, camera, positions_m) for camera in self.cameras])
        return log_likelihood(self.observed_blurred, blur(rendered, self.blur_px), self.sd)

    def start(self, positions_m: np.ndarray) -> float:
        """Lay out every body's layer at ``positions_m``; returns the state's log-likelihood."""
        size, bodies = self.settings.resolution_px, len(positions_m)
        self.depth = np.full((len(self.cameras), bodies, size, size), np.inf)
        self.grey = np.zeros((len(self.cameras), bodies, size, size))
        self.patches = [[EMPTY] * bodies for _ in self.cameras]
        for v, camera in enumerate(self.cameras):
            for b in range(bodies):
                self._place(v, b, body_patch(self.mesh, camera, b, positions_m[b]))
        self.images = np.stack([self._composite(v, (0, size, 0, size)) for v in range(len(self.cameras))])
        self.blurred = blur(self.images, self.blur_px)
        self.current_ll = log_likelihood(self.observed_blurred, self.blurred, self.sd)
        self._accepts = 0
        return self.current_ll

    def _place(self, v: int, b: int, patch: Patch) -> None:
        old = self.patches[v][b]
        self.depth[v, b, old.v0:old.v1, old.u0:old.u1] = np.inf
        self.depth[v, b, patch.v0:patch.v1, patch.u0:patch.u1] = patch.depth
        self.grey[v, b, patch.v0:patch.v1, patch.u0:patch.u1] = patch.grey
        self.patches[v][b] = patch

    def _composite(self, v: int, region: tuple[int, int, int, int], depth=None, grey=None) -> np.ndarray:
        v0, v1, u0, u1 = region
        depth = self.depth[v, :, v0:v1, u0:u1] if depth is None else depth
        grey = self.grey[v, :, v0:v1, u0:u1] if grey is None else grey
        nearest = depth.argmin(axis=0)
        covered = np.take_along_axis(depth, nearest[None], axis=0)[0] < np.inf
        return np.where(covered, np.take_along_axis(grey, nearest[None], axis=0)[0], BACKGROUND_GREY)

    def propose(self, body: int, position_m) -> float:
        """The log-likelihood with ``body`` moved to ``position_m`` (kept pending until ``accept``).

        Only the blurred pixels within the kernel's reach (4 sigma) of the changed ones change, so
        the blurred image and the likelihood are updated in that window alone."""
        self._pending, change_ll = [], 0.0
        reach = int(np.ceil(4 * self.blur_px))
        size = self.settings.resolution_px
        for v, camera in enumerate(self.cameras):
            new, old = body_patch(self.mesh, camera, body, position_m), self.patches[v][body]
            boxes = [p for p in (new, old) if p.v1 > p.v0]
            if not boxes:
                self._pending.append(None)
                continue
            v0, v1 = min(p.v0 for p in boxes), max(p.v1 for p in boxes)
            u0, u1 = min(p.u0 for p in boxes), max(p.u1 for p in boxes)
            depth = self.depth[v, :, v0:v1, u0:u1].copy()
            grey = self.grey[v, :, v0:v1, u0:u1].copy()
            depth[body] = np.inf
            depth[body, new.v0 - v0:new.v1 - v0, new.u0 - u0:new.u1 - u0] = new.depth
            grey[body, new.v0 - v0:new.v1 - v0, new.u0 - u0:new.u1 - u0] = new.grey
            image = self._composite(v, (v0, v1, u0, u1), depth, grey)
            change = image - self.images[v, v0:v1, u0:u1]
            r0, r1, c0, c1 = max(v0 - reach, 0), min(v1 + reach, size), max(u0 - reach, 0), min(u1 + reach, size)
            before = self.blurred[v, r0:r1, c0:c1]
            after = before + self._k[r0:r1, v0:v1] @ change @ self._k_t[u0:u1, c0:c1]
            target = self.observed_blurred[v, r0:r1, c0:c1]
            change_ll += float(np.sum((target - before) ** 2) - np.sum((target - after) ** 2))
            self._pending.append((new, (v0, v1, u0, u1), image, (r0, r1, c0, c1), after))
        proposed = self.current_ll + change_ll / (2 * self.sd * self.sd)
        self._proposed = (body, proposed)
        return proposed

    def accept(self) -> None:
        body, proposed = self._proposed
        for v, pending in enumerate(self._pending):
            if pending is not None:
                new, (v0, v1, u0, u1), image, (r0, r1, c0, c1), after = pending
                self._place(v, body, new)
                self.images[v, v0:v1, u0:u1] = image
                self.blurred[v, r0:r1, c0:c1] = after
        self._accepts += 1
        # now and then from scratch, so that sums of window changes cannot drift
        self.current_ll = log_likelihood(self.observed_blurred, self.blurred, self.sd) \
            if self._accepts % 500 == 0 else proposed


class _SingleBodyMoves:
    """The SI's kernel: a Gaussian move of one body's x, y, the bodies of a scan drawn uniformly with
    replacement; a uniform prior, so the likelihood ratio decides."""

    def __init__(self, model: ImageModel, start_m: np.ndarray, dynamic: int, settings: VisionSettings):
        self.model, self.dynamic, self.settings = model, dynamic, settings
        self.state = np.array(start_m, float)
        self.current = model.start(self.state)

    def propose(self, sample: int, rng: np.random.Generator) -> float:
        if sample % self.dynamic == 0:
            self.order = rng.integers(0, self.dynamic, size=self.dynamic)
        self.body = self.order[sample % self.dynamic]
        self.moved = self.state[self.body].copy()
        self.moved[:2] += self.settings.proposal_sd_m * rng.standard_normal(2)
        self.candidate = self.model.propose(self.body, self.moved)
        return self.candidate - self.current

    def accept(self) -> None:
        self.model.accept()
        self.state[self.body], self.current = self.moved, self.candidate

    def after(self, sample: int, accepted: bool, rng: np.random.Generator) -> None:
        pass

    def keep(self) -> tuple[np.ndarray, float]:
        return self.state[:self.dynamic].copy(), self.current


def run_chain(model: ImageModel, start_m: np.ndarray, dynamic: int, settings: VisionSettings,
              rng: np.random.Generator) -> Chain:
    """``settings.chain_samples`` single-body updates of the first ``dynamic`` bodies' x, y."""
    kernel = _SingleBodyMoves(model, start_m, dynamic, settings)
    run = run_metropolis(kernel, settings.chain_samples, settings.burn_in, rng, kernel.keep)
    return Chain(positions_m=np.array([state for state, _ in run.kept]),
                 log_likelihood=np.array([ll for _, ll in run.kept]), acceptance_rate=run.acceptance_rate,
                 proposals=settings.chain_samples, accepted=run.accepted)
