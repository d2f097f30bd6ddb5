"""The SI's Bayesian vision system: scene samples inferred from images (Fig. S8).

- camera.py: the one pinhole camera model (CameraInfo's conventions), the SI's three viewpoints 45
  degrees apart, and a robot camera from its camera_info;
- render.py: a z-buffered numpy rasteriser of the bodies' hulls into grey images and depth;
- tinyrenderer.py: the same views from pybullet's renderer, evidence independent of ours;
- likelihood.py: the Gaussian blur and the per-pixel normal likelihood;
- mcmc.py: Metropolis-Hastings over the blocks' horizontal positions (an injected Generator);
- perception.py: the IPE's k scene samples drawn from that posterior (``perception="vision"``);
- depth.py: the same idea for a robot's depth camera: the posterior over objects' x, y, yaw (and
  each camera's range offset) given depth images (``perception="depth"``); its likelihood in
  depth_model.py, a robot's files (image, camera_info, pose) read in depth_io.py;
- sources.py: vision and depth registered as perception sources (engine.perceptions), depth's
  evidence (options, topics, parameters) in depth_source.py; scene_pose.py: a posterior's state as
  a scene, for both chains.

ROS-free, like the rest of the engine.
"""

from .camera import PinholeCamera, camera_from_info, default_cameras, look_at
from .likelihood import VisionSettings, blur, log_likelihood
from .mcmc import Chain, effective_sample_size, run_chain
from .perception import PerceivedScenes, perceive
from .render import render, render_views

__all__ = ["Chain", "PerceivedScenes", "PinholeCamera", "VisionSettings", "blur", "camera_from_info", "default_cameras", "look_at",
           "effective_sample_size", "log_likelihood", "perceive", "render", "render_views", "run_chain"]
