"""``ipe experiment NAME``: the paper's model analyses, one module per report.

Each module has ``compute(opts, map_fn)``, which runs the model and the statistics and returns a frozen
result, and ``render(result, opts)``, which turns it into a :class:`~ipe_ros.analysis.report.Report`
(JSON, Markdown, plots); ``run`` does both. ``quick`` shrinks stimuli, samples and grids so a report
runs within CI's budget; the full form uses the paper's sizes. Every report states its parameters
and seed, and which stimulus file (or generated set) it used.
"""

from __future__ import annotations

from typing import Callable

from ..report import Report
from . import bump, direction, fall, far, features, mass, samples, vision
from .common import Options

EXPERIMENTS: dict[str, Callable[[Options, object], Report]] = {
    "fall": fall.run,
    "direction": direction.run,
    "mass": mass.run,
    "far": far.run,
    "bump": bump.run,
    "samples": samples.run,
    "features": features.run,
    "vision": vision.run,
}

__all__ = ["EXPERIMENTS", "Options"]
