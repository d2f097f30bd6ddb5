"""The IPE's input from vision: k scene samples drawn from the image posterior instead of Gaussian sigma.

The scene as given is rendered from the cameras (the SI's synthetic evidence; a robot could pass its
own images), a Metropolis-Hastings chain explores the blocks' horizontal positions, and k states
spread over the chain become k scenes, each then separated and simulated like any IPE sample.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..scene.bodies import Scene
from .camera import PinholeCamera, cameras_for
from .likelihood import VisionSettings
from .mcmc import Chain, ImageModel, run_chain
from .render import render_views, scene_mesh
from .scene_pose import scene_at_pose

#: A chain must give at least this many effective samples per IPE sample asked ("roughly independent").
MIN_ESS_PER_SAMPLE = 0.5


@dataclass(frozen=True)
class PerceivedScenes:
    """k scenes from the vision posterior, with how well the chain mixed."""

    scenes: tuple[Scene, ...]
    acceptance_rate: float
    effective_sample_size: float
    chain_samples: int
    burn_in: int
    chain: Chain
    refined: Scene | None = None  # the SI's vision system reports no single refined scene

    def with_samples(self, k: int) -> "PerceivedScenes":
        """k of the scenes, spread evenly over those kept (no new chain)."""
        if not 1 <= k <= len(self.scenes):
            raise ConfigError("samples", f"the vision chain keeps {len(self.scenes)} scenes, fewer than the {k} "
                                         "samples asked; ask for fewer")
        return dataclasses.replace(self, scenes=tuple(self.scenes[i * len(self.scenes) // k] for i in range(k)))

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "vision", "acceptance_rate": self.acceptance_rate,
                "effective_sample_size": self.effective_sample_size, "chain_samples": self.chain_samples,
                "burn_in": self.burn_in, "samples": len(self.scenes)}


def perceive(scene: Scene, k: int, settings: VisionSettings, rng: np.random.Generator,
             cameras: tuple[PinholeCamera, ...] | None = None, observed: np.ndarray | None = None,
             check_ess: bool = True) -> PerceivedScenes:
    """Run the chain on the scene's images and return k scenes spread over it.

    Raises ConfigError naming ``vision.chain_samples`` when the chain gives fewer than
    MIN_ESS_PER_SAMPLE x k effective samples (the k scenes would not be roughly independent)."""
    cameras = cameras or cameras_for(scene, settings)
    mesh = scene_mesh(scene)
    if observed is None:
        observed = render_views(mesh, cameras)
    model = ImageModel(mesh, cameras, observed, settings)
    dynamic = len(scene.dynamic_objects)
    chain = run_chain(model, mesh.positions_m, dynamic, settings, rng)
    ess = chain.effective_sample_size
    kept = len(chain.positions_m)
    if k > kept or (check_ess and ess < MIN_ESS_PER_SAMPLE * k):
        raise ConfigError("vision.chain_samples",
                          f"the chain of {settings.chain_samples} samples ({kept} after burn-in) gave an effective "
                          f"sample size of {ess:.0f}, too few for {k} roughly independent scene samples (needs "
                          f">= {MIN_ESS_PER_SAMPLE * k:g}); lengthen the chain or ask for fewer samples")
    scenes = tuple(scene_at_pose(scene, state) for state in chain.thinned(k))
    return PerceivedScenes(scenes=scenes, acceptance_rate=chain.acceptance_rate, effective_sample_size=ess,
                           chain_samples=settings.chain_samples, burn_in=settings.burn_in, chain=chain)


@dataclass(frozen=True)
class PerceptionTask:
    """One chain for ``predict`` (picklable, for a worker process): ``seed`` entropy for its Generator."""

    scene: Scene
    k: int
    settings: VisionSettings | None
    seed: tuple[int, ...]


def perceive_task(task: PerceptionTask) -> PerceivedScenes:
    return perceive(task.scene, task.k, task.settings or VisionSettings(),
                    np.random.default_rng(np.random.SeedSequence(list(task.seed))))
