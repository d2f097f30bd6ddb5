"""The SI's Bayesian vision system: scene samples inferred from images (Fig. S8).

- camera.py: pinhole cameras around a scene (the SI's three viewpoints 45 degrees apart);
- render.py: a z-buffered numpy rasteriser of the bodies' hulls into grey images;
- likelihood.py: the Gaussian blur and the per-pixel normal likelihood;
- mcmc.py: Metropolis-Hastings over the blocks' horizontal positions (an injected Generator);
- perception.py: the IPE's k scene samples drawn from that posterior (``perception="vision"``);
- depth.py: the same idea for a robot's depth camera: the posterior over objects' x, y, yaw given
  depth images (``perception="depth"``).

ROS-free, like the rest of the engine.
"""

from .camera import Camera, default_cameras
from .likelihood import VisionSettings, blur, log_likelihood
from .mcmc import Chain, effective_sample_size, run_chain
from .perception import PerceivedScenes, perceive
from .render import render, render_views

__all__ = ["Camera", "Chain", "PerceivedScenes", "VisionSettings", "blur", "default_cameras",
           "effective_sample_size", "log_likelihood", "perceive", "render", "render_views", "run_chain"]
