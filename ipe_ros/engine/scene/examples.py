"""The scenes that ship with the package (used by ``ipe demo``, the ROS demo and the benchmarks)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def example_scene_path() -> Path:
    """The packaged example tower: a generated paper-style tower of 10 blocks that stands but looks risky."""
    return Path(str(resources.files("ipe_ros") / "data" / "example_tower.json"))
