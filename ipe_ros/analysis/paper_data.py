"""The authors' data set (``../shared/data/battaglia2013``): where it is, and their simulation's outcomes.

Used by ``ipe experiment``, the tests and the benchmarks alike. Nothing here ships the data: every
reader says where it looked when the data set is absent.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

#: The authors' outcomes of their own ground-truth simulation, one row per (dataset, stimulus).
OUTCOMES_FILE = "ground_truth_stability.csv"
#: The dataset of OUTCOMES_FILE that holds Exp. 1's towers (willitfall.csv).
EXP1_DATASET = "stability_original_fall"


def shared_data_dir() -> Path:
    """``IPE_SHARED_DATA`` or ../shared/data/battaglia2013 beside the repository."""
    env = os.environ.get("IPE_SHARED_DATA")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2].parent / "shared" / "data" / "battaglia2013"


@dataclass(frozen=True)
class AuthorsOutcome:
    """One stimulus under the authors' ground-truth simulation: how many blocks fell, and whether it stood."""

    blocks_fell: int
    stable: bool


def authors_outcomes(dataset: str = EXP1_DATASET, data_dir: Path | None = None) -> dict[str, AuthorsOutcome]:
    """Stimulus name -> the authors' outcome, for one dataset; {} when the file is absent."""
    path = (data_dir or shared_data_dir()) / OUTCOMES_FILE
    if not path.exists():
        return {}
    with path.open(newline="") as handle:
        return {r["stimulus"]: AuthorsOutcome(blocks_fell=int(r["nfell"]), stable=r["stable"] == "1")
                for r in csv.DictReader(handle) if r["dataset"] == dataset}
