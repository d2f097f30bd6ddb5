"""The intuitive physics engine, free of ROS: scenes, sampling, simulation, queries, Monte Carlo.

Its rooms (docs/architecture.md): ``scene`` (what a scene is, its formats, scenes made here),
``sampling`` (the one Monte Carlo loop, predictions, one sample end to end, the answer),
``simulation`` (pybullet worlds and the rollout loop), ``query`` (what is asked of a rollout),
``checking`` (answers checked against converged physics), ``vision`` (perception from images),
``actions`` (robot questions), ``compute`` (where samples run and are kept); at the top, the request:
its inputs, checks, defaults and errors, and the perception registry. This module re-exports what a
caller needs. Importing this package never imports rclpy or any ROS message package (a test checks it).
"""

from .config import PRESETS, ModelConfig, SimSettings, preset
from .vision import sources as _vision_sources  # noqa: F401 - registers vision and depth perception
from .query import ALL_QUERIES, QuerySpec, parse_queries
from .errors import ConfigError, PhysicsError, SceneError
from .sampling.estimate import Prediction
from .compute.pool import WorkerPool
from .predict import AdaptiveStop, Context, Request, predict, predict_many
from .scene.bodies import Body, Box, Floor, Scene, Table
from .scene.validation import validate_scene
from .scene.shapes import BoxShape, Capsule, Compound, CompoundPart, ConvexHull, Cylinder, Sphere
from .scene.files import load_scenes, scenes_from_tower_csv
from .scene.format import scene_from_dict, scene_to_dict, scenes_from_json

__all__ = [
    "ALL_QUERIES", "PRESETS", "AdaptiveStop", "Body", "Box", "BoxShape", "Capsule", "Compound", "CompoundPart",
    "Context", "Request",
    "ConvexHull", "Cylinder", "Sphere", "ConfigError", "Floor", "ModelConfig", "PhysicsError", "Prediction",
    "QuerySpec", "Scene", "SceneError", "SimSettings", "Table", "WorkerPool", "load_scenes",
    "parse_queries", "predict", "predict_many", "preset", "scene_from_dict", "scene_to_dict", "scenes_from_json",
    "scenes_from_tower_csv", "validate_scene",
]
