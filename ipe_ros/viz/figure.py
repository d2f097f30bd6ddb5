"""A prediction as one picture (PNG, matplotlib): the scene coloured by each object's fall probability,
a few of the sampled rollouts (their noisy start outlined, their end state filled, red where an
object fell), and the answer in the title. Side view: x right, z up, as the robot sees a tower."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..engine.scene import shapes
from ..engine.sampling.estimate import Prediction
from ..engine.scene.bodies import Scene
from .palette import SUPPORT_RGB, group_rgb, risk_rgb

FELL_RGB = (0.85, 0.1, 0.1)


def _side_outline(shape, position_m, orientation_xyzw, about_centre_of_mass: bool) -> np.ndarray:
    """The body's x-z silhouette as a closed polygon (the 2-D hull of its surface points)."""
    from scipy.spatial import ConvexHull

    points = shapes.surface_points(shape)
    if about_centre_of_mass:  # rollouts report centres of mass
        points = points - shapes.centre_of_mass_m(shape)
    points = points @ shapes.rotation_matrix(orientation_xyzw).T + np.asarray(position_m, float)
    xz = points[:, [0, 2]]
    return xz[ConvexHull(xz).vertices]


def _summary(prediction: Prediction) -> str:
    parts = []
    if prediction.fall_fraction is not None:
        lo, hi = prediction.fall_fraction_ci95
        parts.append(f"fall fraction {prediction.fall_fraction:.2f} [{lo:.2f}, {hi:.2f}]")
    if prediction.any_fall_probability is not None:
        parts.append(f"P(anything falls) {prediction.any_fall_probability:.2f}")
    if prediction.direction_rad is not None:
        parts.append(f"direction {math.degrees(prediction.direction_rad):.0f} deg "
                     f"(decisiveness {prediction.direction_decisiveness:.2f})")
    parts.append(f"k = {prediction.samples}")
    return " | ".join(parts)


def draw_prediction(path: str | Path, scene: Scene, prediction: Prediction, rollouts: int = 3) -> None:
    """Write the picture to ``path``: the answer on the scene, then ``rollouts`` sampled rollouts."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon

    samples = [o for o in prediction.outcomes if o.ok and o.rollouts][:rollouts]
    fig, axes = plt.subplots(1, 1 + len(samples), figsize=(3.2 * (1 + len(samples)), 3.8), sharey=True,
                             squeeze=False)
    axes = axes[0]
    dynamic = scene.dynamic_objects
    risk = prediction.object_fall_probability or {}
    statics = [b for b in scene.objects if b.static]

    def background(ax) -> None:
        ax.axhline(scene.support.top_m, color=SUPPORT_RGB, linewidth=2)
        for body in statics:
            ax.add_patch(Polygon(_side_outline(body.shape, body.position_m, body.orientation_xyzw, False),
                                 facecolor=SUPPORT_RGB, edgecolor="none"))

    ax = axes[0]
    background(ax)
    for body in dynamic:
        colour = risk_rgb(risk[body.name]) if body.name in risk else group_rgb(body.group)
        ax.add_patch(Polygon(_side_outline(body.shape, body.position_m, body.orientation_xyzw, False),
                             facecolor=colour, edgecolor="black", linewidth=0.5))
    if prediction.direction_rad is not None and dynamic:
        top = max(b.position_m[2] + b.extents_m[2] / 2 for b in dynamic)
        x0 = float(np.mean([b.position_m[0] for b in dynamic]))
        # the fall direction's x component, as long as a third of the scene's height at decisiveness 1
        length = (top - scene.support.top_m) / 3 * (prediction.direction_decisiveness or 0.0)
        y = top + 0.05 * (top - scene.support.top_m)
        ax.annotate("", xy=(x0 + length * math.cos(prediction.direction_rad), y), xytext=(x0, y),
                    arrowprops=dict(arrowstyle="->", color=FELL_RGB, linewidth=2))
    ax.set_title("the answer: P(fall) per object\n(green 0, yellow 0.5, red 1)", fontsize=9)
    for ax, outcome in zip(axes[1:], samples):
        background(ax)
        rollout = outcome.rollouts[0]
        for i, body in enumerate(dynamic):
            ax.add_patch(Polygon(_side_outline(body.shape, outcome.initial_positions_m[i],
                                               outcome.initial_orientations_xyzw[i], True),
                                 fill=False, edgecolor="grey", linestyle=":", linewidth=0.8))
            fell = rollout.fallen is not None and bool(rollout.fallen[i])
            ax.add_patch(Polygon(_side_outline(body.shape, rollout.final_positions_m[i],
                                               rollout.final_orientations_xyzw[i], True),
                                 facecolor=FELL_RGB if fell else group_rgb(body.group), edgecolor="black",
                                 linewidth=0.5, alpha=0.9))
        fallen = "?" if rollout.fallen is None else int(np.sum(rollout.fallen))
        ax.set_title(f"sample {outcome.index}: noisy start (dotted),\nend state ({fallen} fell, red)", fontsize=9)
    for ax in axes:
        ax.set_aspect("equal", adjustable="datalim")
        ax.autoscale_view()
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("z (m)")
    fig.suptitle(f"{scene.name}: {_summary(prediction)}", fontsize=10)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
