"""People's yes/no responses per stimulus: the share saying yes and how many answered.

A CSV with a header; by default the columns of ``../shared/data/physion_dominoes/people.csv``:
``stimulus``, ``people_p_yes`` (share in 0..1), ``responders`` (> 0) and, optionally, ``hit_zone``
(the true outcome, 0 or 1: the report's accuracy). Each problem is refused in one line naming the
file, its line and the column.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...engine import ConfigError

#: the largest responses file read (a typo naming a video would otherwise be read whole)
MAX_BYTES = 64 * 1024 * 1024


@dataclass(frozen=True)
class Columns:
    stimulus: str = "stimulus"
    share: str = "people_p_yes"
    responders: str = "responders"
    truth: str | None = "hit_zone"


@dataclass(frozen=True)
class Responses:
    """Per stimulus (in the file's order): the share of ``responders`` who said yes, and the true
    outcome (None: the file gives none)."""

    stimuli: tuple[str, ...]
    yes_share: np.ndarray
    responders: np.ndarray
    truth: np.ndarray | None = None

    @property
    def yes_counts(self) -> np.ndarray:
        return np.rint(self.yes_share * self.responders)

    def subset(self, names) -> "Responses":
        index = {n: i for i, n in enumerate(self.stimuli)}
        rows = np.array([index[n] for n in names], dtype=int)
        return Responses(tuple(names), self.yes_share[rows], self.responders[rows],
                         None if self.truth is None else self.truth[rows])


def load_responses(path: str | Path, columns: Columns = Columns()) -> Responses:
    path = Path(path)
    if not path.is_file():
        raise ConfigError("responses", f"no such file {str(path)!r}")
    if path.stat().st_size > MAX_BYTES:
        raise ConfigError("responses", f"{path.name} is over {MAX_BYTES // 2**20} MiB: is it the responses CSV?")
    names, shares, counts, truths = [], [], [], []
    with path.open(newline="", encoding="utf-8", errors="replace") as handle:
        reader = csv.DictReader(handle)
        wanted = [columns.stimulus, columns.share, columns.responders]
        missing = [c for c in wanted if c not in (reader.fieldnames or [])]
        if missing:
            raise ConfigError("responses", f"{path.name} lacks the column(s) {', '.join(missing)} (it has "
                                           f"{', '.join(reader.fieldnames or []) or 'no header'})")
        truth_column = columns.truth if columns.truth in (reader.fieldnames or []) else None
        seen: dict[str, int] = {}
        for line, row in enumerate(reader, start=2):
            where = f"{path.name} line {line}"
            name = (row[columns.stimulus] or "").strip()
            if not name:
                raise ConfigError("responses", f"{where}: {columns.stimulus} is empty")
            if name in seen:
                raise ConfigError("responses", f"{where}: stimulus {name!r} again (first on line {seen[name]}): "
                                               "give one row per stimulus")
            seen[name] = line
            share = _number(row[columns.share], where, columns.share)
            if not 0 <= share <= 1:
                raise ConfigError("responses", f"{where}: {columns.share} must be a share in 0..1, got {share:g}")
            count = _number(row[columns.responders], where, columns.responders)
            if count < 1 or count != int(count):
                raise ConfigError("responses", f"{where}: {columns.responders} must be a whole number >= 1, "
                                               f"got {count:g}")
            truth = math.nan
            if truth_column is not None and (row[truth_column] or "").strip():
                truth = _number(row[truth_column], where, truth_column)
                if truth not in (0, 1):
                    raise ConfigError("responses", f"{where}: {truth_column} must be 0 or 1, got {truth:g}")
            names.append(name), shares.append(share), counts.append(int(count)), truths.append(truth)
    if not names:
        raise ConfigError("responses", f"{path.name} holds no stimuli")
    truth_array = np.array(truths) if truth_column is not None and not np.isnan(truths).any() else None
    return Responses(tuple(names), np.array(shares), np.array(counts), truth_array)


def _number(text: str | None, where: str, column: str) -> float:
    try:
        value = float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ConfigError("responses", f"{where}: {column} {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ConfigError("responses", f"{where}: {column} must be finite, got {text!r}")
    return value


def matched(responses: Responses, scene_names) -> Responses:
    """The responses in the scenes' order; a stimulus without a scene is refused (a scene without
    responses is left out of the fit)."""
    scene_names = list(scene_names)
    known = set(scene_names)
    lost = [n for n in responses.stimuli if n not in known]
    if lost:
        raise ConfigError("responses", f"stimulus {lost[0]!r} has no scene of that name"
                                       + (f" ({len(lost) - 1} more)" if len(lost) > 1 else "")
                                       + ": give the scenes file the responses were collected on")
    answered = set(responses.stimuli)
    return responses.subset([n for n in scene_names if n in answered])
