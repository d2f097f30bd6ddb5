"""The SI's image likelihood: blurred images compared pixel by pixel under a normal density.

SI "Bayesian Vision System": three 256 x 256 8-bit images, each filtered with a normalised 2-D
Gaussian blur of scale 11 pixels; the likelihood is the product of per-pixel normal densities with
an SD of 128 grey levels between the observed and the rendered (blurred) image.

Images may be rendered at another resolution to save time: blur scale and SD are given at the
SI's 256 pixels and scaled with the resolution (the blur in pixels with it, the SD so that the
log-likelihood, a sum over pixels, keeps its size: sd x resolution / 256).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import ConfigError

REFERENCE_RESOLUTION_PX = 256


@dataclass(frozen=True)
class VisionSettings:
    """The vision system's settings (SI values as defaults).

    resolution_px: rendered image size (square); blur_px and likelihood_sd_grey are at 256 pixels.
    views, separation_deg: how many images, and the turn between viewpoints.
    chain_samples, burn_in: Metropolis-Hastings samples (one block update each) and those discarded.
    proposal_sd_m: SD of a proposal's horizontal move (0.2 short sides of the paper's 0.2 m blocks).
    """

    resolution_px: int = 256
    blur_px: float = 11.0
    likelihood_sd_grey: float = 128.0
    views: int = 3
    separation_deg: float = 45.0
    chain_samples: int = 5000
    burn_in: int = 1000
    proposal_sd_m: float = 0.04

    def __post_init__(self) -> None:
        if not isinstance(self.resolution_px, int) or not 16 <= self.resolution_px <= 1024:
            raise ConfigError("vision.resolution_px", f"must be an integer in [16, 1024], got {self.resolution_px!r}")
        for name in ("blur_px", "likelihood_sd_grey", "proposal_sd_m"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
                raise ConfigError(f"vision.{name}", f"must be a finite number > 0, got {value!r}")
        if not isinstance(self.views, int) or not 1 <= self.views <= 16:
            raise ConfigError("vision.views", f"must be an integer in [1, 16], got {self.views!r}")
        if not isinstance(self.chain_samples, int) or self.chain_samples < 1:
            raise ConfigError("vision.chain_samples", f"must be an integer >= 1, got {self.chain_samples!r}")
        if not isinstance(self.burn_in, int) or not 0 <= self.burn_in < self.chain_samples:
            raise ConfigError("vision.burn_in", f"must be an integer in [0, chain_samples), got {self.burn_in!r}")

    @property
    def scale(self) -> float:
        return self.resolution_px / REFERENCE_RESOLUTION_PX

    @property
    def blur_at_resolution_px(self) -> float:
        return self.blur_px * self.scale

    @property
    def sd_at_resolution_grey(self) -> float:
        return self.likelihood_sd_grey * self.scale


@lru_cache(maxsize=8)
def blur_matrices(size: int, sigma_px: float) -> tuple[np.ndarray, np.ndarray]:
    """A normalised 1-D Gaussian (cut at 4 sigma, as scipy's) as a (size, size) matrix K and its
    transpose: blur(image) = K @ image @ K.T, each row renormalised where the kernel leaves the
    image, so a plain background stays plain."""
    x = np.arange(size)
    offset = x[:, None] - x[None, :]
    k = np.where(np.abs(offset) <= 4 * sigma_px, np.exp(-(offset ** 2) / (2 * sigma_px ** 2)), 0.0)
    k /= k.sum(axis=1, keepdims=True)
    return k, np.ascontiguousarray(k.T)


def blur(images: np.ndarray, sigma_px: float) -> np.ndarray:
    """Normalised separable Gaussian blur of (..., size, size) images."""
    k, k_t = blur_matrices(images.shape[-1], float(sigma_px))
    return np.matmul(np.matmul(k, images), k_t)


def log_likelihood(observed_blurred: np.ndarray, rendered_blurred: np.ndarray, sd_grey: float) -> float:
    """Sum over pixels of log N(observed; rendered, sd), without the constant."""
    diff = np.asarray(observed_blurred, float) - np.asarray(rendered_blurred, float)
    return float(-0.5 * np.sum(diff * diff) / (sd_grey * sd_grey))
