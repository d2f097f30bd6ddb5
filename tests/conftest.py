"""Shared fixtures. Engine tests need no ROS; data tests read ../shared and skip when it is absent."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# DDS stays on loopback for any test that starts rclpy (set before rclpy is imported anywhere).
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from hypothesis import HealthCheck, settings  # noqa: E402

from ipe_ros.analysis.paper_data import shared_data_dir  # noqa: E402 - after the DDS setting

# Fuzz tests (tests/test_fuzz.py): "ci" keeps them to about a minute; "soak" is for long local runs
# (--hypothesis-profile soak). No example database: CI runs from a clean clone anyway.
settings.register_profile("ci", max_examples=60, deadline=None, database=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("soak", max_examples=20_000, deadline=None, database=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci")

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = shared_data_dir()


def shared_file(name: str) -> Path:
    """Path of a file of the paper's data set, or skip the test saying why."""
    path = SHARED_DATA / name
    if not path.exists():
        pytest.skip(f"{path} is absent: the paper's data (../shared/data/battaglia2013) is needed "
                    "for this check; set IPE_SHARED_DATA to its folder")
    return path


@pytest.fixture(scope="session")
def pool():
    """One persistent pool of 2 worker processes for the whole session."""
    from ipe_ros.engine import WorkerPool

    with WorkerPool(2) as workers:
        yield workers
