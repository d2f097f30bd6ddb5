"""The intuitive physics engine, free of ROS: scenes, sampling, simulation, queries, Monte Carlo.

Importing this package never imports rclpy or any ROS message package (a test checks it).
"""

from .config import PRESETS, ModelConfig, SimSettings, preset
from .query import ALL_QUERIES, QuerySpec, parse_queries
from .errors import ConfigError, PhysicsError, SceneError
from .estimate import Prediction
from .pool import WorkerPool
from .sampler import AdaptiveStop, predict, predict_many
from .scene import Body, Box, Floor, Scene, Table, validate_scene
from .shapes import BoxShape, Capsule, Compound, CompoundPart, ConvexHull, Cylinder, Sphere
from .scene_files import load_scenes, scenes_from_tower_csv
from .scene_io import scene_from_dict, scene_to_dict, scenes_from_json

__all__ = [
    "ALL_QUERIES", "PRESETS", "AdaptiveStop", "Body", "Box", "BoxShape", "Capsule", "Compound", "CompoundPart",
    "ConvexHull", "Cylinder", "Sphere", "ConfigError", "Floor", "ModelConfig", "PhysicsError", "Prediction",
    "QuerySpec", "Scene", "SceneError", "SimSettings", "Table", "WorkerPool", "load_scenes",
    "parse_queries", "predict", "predict_many", "preset", "scene_from_dict", "scene_to_dict", "scenes_from_json",
    "scenes_from_tower_csv", "validate_scene",
]
