"""Exp. 5 (Bump?): predictions over bump direction and magnitude, cued and uncued, with and without walls."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ...engine import ModelConfig, predict_many, preset
from ...engine.scene.generators import generate_tables
from .. import stats
from ..report import Report, pyplot
from ..reporting import steps
from ..runs import (PAPER_BUMP_PHIS, PAPER_SIGMA, PHI_M_S2_PER_PAPER_UNIT, map_batches, phi_m_s2, sigma_m,
                    stimulus_seed)
from .common import BUMP, HumanComparison, Options, compare_with_people, render_people

#: The comparisons between model variants: (label, variant a, variant b, compare once per scene).
COMPARISONS = (("cued vs cue-insensitive", "cued", "cue_insensitive", False),
               ("cued vs obstacle-insensitive", "cued", "obstacle_insensitive", False),
               ("uncued vs obstacle-insensitive (uncued), one per scene", "uncued", "obstacle_insensitive_uncued",
                True))


@dataclass(frozen=True)
class BumpGrid:
    """Per scene: bump ratio and fell-off fraction per (direction, magnitude) cell, averaged over
    samples (NaN where nothing fell off), and the pooled per-rollout values per cell."""

    directions_rad: np.ndarray
    phis_paper: np.ndarray
    ratio: np.ndarray          # (scenes, directions, magnitudes)
    fell_off: np.ndarray       # (scenes, directions, magnitudes), fraction of all blocks
    ratio_sum: np.ndarray      # per cell: sum of defined per-rollout ratios
    ratio_count: np.ndarray    # per cell: how many rollouts had something fall off

    def judgment(self, scene: int, cells: np.ndarray) -> float:
        """The model's answer over the chosen direction cells (all magnitudes): mean ratio over rollouts."""
        count = self.ratio_count[scene][cells].sum()
        return float(self.ratio_sum[scene][cells].sum() / count) if count else math.nan


def bump_grid(scenes, directions, phis, k: int, opts: Options, map_fn, label: str) -> BumpGrid:
    settings = preset(opts.preset)
    shape = (len(scenes), len(directions), len(phis))
    ratio, fell = np.full(shape, np.nan), np.zeros(shape)
    ratio_sum, ratio_count = np.zeros(shape), np.zeros(shape)
    models = [ModelConfig(sigma_m=sigma_m(PAPER_SIGMA), phi_m_s2=tuple(phi_m_s2(p) for p in phis), samples=k,
                          force_direction_rad=float(theta), cue_half_width_rad=0.0) for theta in directions]
    # a fixed direction each (no cue spread); every magnitude is simulated for each noisy sample. Several
    # tables' directions go in one map, as the tower reports send several towers: one table alone
    # (directions x k samples) is fewer tasks than a large cluster has workers
    batches = map_batches(len(scenes), len(directions) * k)
    for batch in steps(batches, f"{label} ({len(scenes)} scenes, {len(batches[0]) if batches else 0} per batch)",
                       every=1):
        requests = []
        for s in batch:
            # a block configuration keeps its seed on every table, with or without walls (common
            # random numbers: differences between tables are the tables' alone)
            configuration = scenes[s].name.removesuffix("_nowalls").rsplit("_", 1)[0]
            seed = stimulus_seed(opts.seed, configuration)
            requests += [(scenes[s], model, seed) for model in models]
        answers = iter(predict_many(requests, settings, BUMP, map_fn))
        for s in batch:
            for d in range(len(directions)):
                pred = next(answers)
                for m in range(len(phis)):
                    rollouts = [o.rollouts[m] for o in pred.outcomes if o.ok]
                    values = [r.get("bump_ratio") for r in rollouts if r.get("bump_ratio") is not None]
                    ratio_sum[s, d, m], ratio_count[s, d, m] = sum(values), len(values)
                    ratio[s, d, m] = np.mean(values) if values else np.nan
                    fell[s, d, m] = np.mean([r.value("fell_off").mean() for r in rollouts]) if rollouts else np.nan
    return BumpGrid(directions_rad=np.asarray(directions), phis_paper=np.asarray(phis), ratio=ratio, fell_off=fell,
                    ratio_sum=ratio_sum, ratio_count=ratio_count)


def cued_cells(directions: np.ndarray, cue: float, half_width: float = math.pi / 4) -> np.ndarray:
    offset = np.abs(np.angle(np.exp(1j * (directions - cue))))
    return offset <= half_width + 1e-9


def without_walls(scene):
    return dataclasses.replace(scene, name=scene.name + "_nowalls",
                               support=dataclasses.replace(scene.support, obstacles=()))


@dataclass(frozen=True)
class BumpResult:
    scenes: tuple
    k: int
    phis: tuple[float, ...]
    configurations: int
    tables: tuple[str, ...]
    grid: BumpGrid
    stimuli: tuple[dict, ...]      # per (scene, cue): each variant's judgment
    comparisons: dict             # label -> bootstrap r
    compared: dict                # label -> stimuli compared
    blocks_per_scene: np.ndarray
    fell_off_lowest_phi: float    # mean blocks knocked off per bump
    fell_off_highest_phi: float
    people: HumanComparison | None


def compute(opts: Options, map_fn) -> BumpResult:
    n_dir = 4 if opts.quick else 16
    phis = (22.0, 76.0) if opts.quick else PAPER_BUMP_PHIS
    k = opts.samples or (2 if opts.quick else 12)
    configurations = 1 if opts.quick else 12
    tables = ("T0", "T3") if opts.quick else ("T0", "T1", "T2", "T3", "T4")
    scenes = generate_tables(opts.seed, configurations=configurations, tables=tables)
    if opts.stimuli is not None:
        scenes = scenes[:opts.stimuli]
    directions = np.arange(n_dir) * 2 * math.pi / n_dir
    walls = bump_grid(scenes, directions, phis, k, opts, map_fn, "walls")
    walled = [i for i, s in enumerate(scenes) if s.support.obstacles]
    no_walls = bump_grid([without_walls(scenes[i]) for i in walled], directions, phis, k, opts, map_fn, "no walls") \
        if walled else None

    def no_walls_judgment(i: int, cells: np.ndarray) -> float:
        if i not in walled:
            return walls.judgment(i, cells)  # a flat table has no obstacles to ignore
        return no_walls.judgment(walled.index(i), cells)

    everywhere = np.ones(n_dir, bool)
    rng = opts.rng("cues")
    stimuli = []
    for i, scene in enumerate(scenes):
        first = int(rng.integers(n_dir))
        for cue_index in (first, (first + n_dir // 2) % n_dir):  # two opposite cued directions per scene
            cells = cued_cells(directions, directions[cue_index])
            stimuli.append({"scene": scene.name, "cue_deg": math.degrees(directions[cue_index]),
                            "cued": walls.judgment(i, cells), "uncued": walls.judgment(i, everywhere),
                            "cue_insensitive": walls.judgment(i, everywhere),
                            "obstacle_insensitive": no_walls_judgment(i, cells),
                            "obstacle_insensitive_uncued": no_walls_judgment(i, everywhere)})
    variants = {key: np.array([s[key] for s in stimuli]) for key in stimuli[0] if key not in ("scene", "cue_deg")}
    # Uncued answers do not depend on the cue: compare them once per scene, not once per cue
    # (duplicated stimuli would make the bootstrap interval too narrow).
    one_per_scene = np.zeros(len(stimuli), bool)
    one_per_scene[::2] = True
    comparisons, compared = {}, {}
    for label, a, b, once in COMPARISONS:
        keep = np.isfinite(variants[a]) & np.isfinite(variants[b]) & (one_per_scene if once else True)
        if keep.sum() >= 3:
            comparisons[label] = stats.bootstrap_pearson(variants[a][keep], variants[b][keep],
                                                         n_resamples=opts.resamples, rng=opts.rng(label))
            compared[label] = int(keep.sum())
    n_blocks = np.array([len(s.dynamic_objects) for s in scenes])[:, None]
    names = tuple(f"{s['scene']}@cue={s['cue_deg']:g}" for s in stimuli)
    people = compare_with_people(opts, names, {"IPE (cued)": variants["cued"],
                                               "cue-insensitive": variants["cue_insensitive"],
                                               "obstacle-insensitive": variants["obstacle_insensitive"]})
    return BumpResult(scenes=tuple(scenes), k=k, phis=tuple(phis), configurations=configurations, tables=tables,
                      grid=walls, stimuli=tuple(stimuli), comparisons=comparisons, compared=compared,
                      blocks_per_scene=n_blocks.ravel(),
                      fell_off_lowest_phi=float(np.nanmean(walls.fell_off[:, :, 0] * n_blocks)),
                      fell_off_highest_phi=float(np.nanmean(walls.fell_off[:, :, -1] * n_blocks)), people=people)


def render(res: BumpResult, opts: Options) -> Report:
    grid, phis, scenes = res.grid, res.phis, res.scenes
    n_dir = len(grid.directions_rad)
    report = Report("bump", "Exp. 5 (Bump?): uncued and cued predictions over bump direction and magnitude",
                    opts.parameters(k=res.k, directions=n_dir, **{"phi (paper units)": list(phis),
                                                                  "block configurations": res.configurations,
                                                                  "tables": list(res.tables)}))
    report.add(f"Stimuli: {len(scenes)} generated table scenes (`generate_tables(seed={opts.seed})`, "
               f"{res.configurations} block configurations x tables {', '.join(res.tables)}; red/yellow halves). "
               f"The paper's 60 scenes are not in the shared data, so these follow its description.", "")
    report.results.update(stimuli=list(res.stimuli), comparisons=res.comparisons, blocks_per_scene=res.blocks_per_scene,
                          blocks_fell_off_at_lowest_phi=res.fell_off_lowest_phi,
                          blocks_fell_off_at_highest_phi=res.fell_off_highest_phi,
                          grid_ratio=grid.ratio, grid_fell_off=grid.fell_off, failed_samples=None)
    report.add(f"## phi: one paper unit read as {PHI_M_S2_PER_PAPER_UNIT:g} m/s² of table acceleration", "",
               f"Mean blocks knocked off per bump at phi = {phis[0]:g}: {res.fell_off_lowest_phi:.2f}; at phi = "
               f"{phis[-1]:g}: {res.fell_off_highest_phi:.2f} (of {res.blocks_per_scene.mean():.1f} per scene). The "
               "paper: phi = 22 'usually caused only one or a few blocks to fall off the table, and phi = 76 caused "
               "many or almost all to fall off'.", "",
               "## Model variants", "",
               "Each stimulus is a scene with a cued direction (two opposite cues per scene). cued: bump directions "
               "within +-45 degrees of the cue, all magnitudes. cue-insensitive: the uncued answer (all directions) "
               "given for the cued question. obstacle-insensitive: the same blocks on the table without its walls.", "")
    report.table(["comparison", "stimuli", "r (median [95% CI])"],
                 [[label, res.compared[label], str(est)] for label, est in res.comparisons.items()])
    _render_disks(report, res, opts)
    render_people(report, res.people, opts)
    return report


def _render_disks(report: Report, res: BumpResult, opts: Options) -> None:
    grid, phis, scenes = res.grid, res.phis, res.scenes
    directions = grid.directions_rad
    n_dir = len(directions)
    plt = pyplot()
    shown = list(range(min(4, len(scenes))))
    fig, axes = plt.subplots(1, len(shown) + 1, subplot_kw={"projection": "polar"},
                             figsize=(3.2 * (len(shown) + 1), 3.4))
    theta_edges = np.append(directions, 2 * math.pi) - math.pi / n_dir
    phi_edges = np.concatenate([[phis[0] - (phis[1] - phis[0]) / 2 if len(phis) > 1 else phis[0] - 1],
                                (np.asarray(phis[:-1]) + np.asarray(phis[1:])) / 2,
                                [phis[-1] + (phis[-1] - phis[-2]) / 2 if len(phis) > 1 else phis[0] + 1]])
    for ax, i in zip(axes, shown):
        mesh = ax.pcolormesh(theta_edges, phi_edges, grid.ratio[i].T, cmap="RdYlBu_r", vmin=0, vmax=1, shading="flat")
        ax.set_title(scenes[i].name.split("_", 3)[-1], fontsize=8)
        ax.set_yticklabels([])
    mean_off = np.nanmean(grid.fell_off, axis=0)
    mesh_off = axes[-1].pcolormesh(theta_edges, phi_edges, mean_off.T, cmap="viridis", vmin=0, vmax=1, shading="flat")
    axes[-1].set_title("fell off (all scenes)", fontsize=8)
    axes[-1].set_yticklabels([])
    fig.colorbar(mesh, ax=axes[:-1].tolist(), shrink=0.6, label="red share of fallen-off blocks")
    fig.colorbar(mesh_off, ax=axes[-1], shrink=0.6, label="fraction fallen off")
    report.figure(fig, opts.out_dir, "disks", "prediction per bump direction (angle) and magnitude (radius)")


def run(opts: Options, map_fn) -> Report:
    return render(compute(opts, map_fn), opts)
