"""``ipe fit --report DIR``: the fit as a Markdown page with figures (model against people per
stimulus, the folds, the likelihood surface), and the same as text for the terminal."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..report import Report, pyplot
from .fit import FitResult


def _point(values: dict) -> str:
    return ", ".join(f"{k} = {v:g}" for k, v in values.items())


def summary_lines(result: FitResult) -> list[str]:
    """The fit in a few lines: folds, held-out scores, parameters with intervals, mapping, cost."""
    ref = result.evaluations[result.reference].values
    lines = [f"readout {result.readout}; {len(result.responses.stimuli)} stimuli, {len(result.folds)} folds, "
             f"k = {result.settings.samples}, reference {_point(ref)}",
             "fold  chosen                                    r (fit)  r (ref)   gain  dLL/stim vs baseline"]
    for f in result.folds:
        gain_ll = (f.fitted.loglik - f.baseline_loglik) / len(f.test)
        lines.append(f"{f.fold:>4}  {_point(result.evaluations[f.chosen].values):<40}  {f.fitted.r:7.3f}  "
                     f"{f.reference.r:7.3f}  {f.fitted.r - f.reference.r:+5.3f}  {gain_ll:+.2f}")
    cv, cr = result.cv, result.cv_reference
    lines.append(f"held out, all folds: r = {cv.r:.3f} (reference {cr.r:.3f}); accuracy against people's majority "
                 f"{cv.accuracy_majority:.2f} (reference {cr.accuracy_majority:.2f})"
                 + (f", against the true outcome {cv.accuracy_truth:.2f} (reference {cr.accuracy_truth:.2f})"
                    if cv.accuracy_truth is not None else ""))
    people_truth = _people_accuracy(result)
    if people_truth is not None:
        lines.append(f"people's majority against the true outcome: {people_truth:.2f}")
    lines.append("fitted on every stimulus: " + ", ".join(
        f"{k} = {v:g} [{result.intervals[k][0]:g}, {result.intervals[k][1]:g}]" for k, v in result.parameters.items())
        + f" (95%, profile likelihood, overdispersion {result.overdispersion:.2f})")
    m = result.mapping
    lines.append(f"mapping: P(yes) = {m.lapse:.3f}/2 + (1 - {m.lapse:.3f}) logistic({m.intercept:.2f} + "
                 f"{m.slope:.2f} logit((p k + 0.5) / (k + 1))), k = {m.samples}")
    total = sum(e.wall_s for e in result.evaluations)
    lines.append(f"cost: {len(result.evaluations)} grid evaluations, {sum(e.rollouts for e in result.evaluations)} "
                 f"rollouts, {total:.0f} s simulating"
                 + (f"; {sum(e.failed_samples for e in result.evaluations)} samples failed"
                    if any(e.failed_samples for e in result.evaluations) else ""))
    return lines


def _people_accuracy(result: FitResult) -> float | None:
    r = result.responses
    return None if r.truth is None else float(np.mean((r.yes_share > 0.5) == (r.truth > 0.5)))


def write_page(result: FitResult, out_dir: Path, parameters: dict) -> Path:
    report = Report("fit", "The IPE fitted to people", parameters)
    report.add("## Summary", "", "```", *summary_lines(result), "```", "")
    report.add("## Folds", "", "Each fold's grid point and mapping are chosen on the other folds' stimuli and scored "
               "on its own; the reference (the paper's parameters) gets its mapping fitted on the same stimuli.", "")
    report.table(["fold", "stimuli", "chosen", "r fit", "r reference", "LL fit", "LL reference", "LL baseline",
                  "accuracy (truth)", "accuracy (majority)"],
                 [[f.fold, len(f.test), _point(result.evaluations[f.chosen].values), f.fitted.r, f.reference.r,
                   f.fitted.loglik, f.reference.loglik, f.baseline_loglik,
                   f.fitted.accuracy_truth if f.fitted.accuracy_truth is not None else float("nan"),
                   f.fitted.accuracy_majority] for f in result.folds])
    report.add("## Cost", "", "Each grid point is evaluated once on every stimulus (common random numbers); the "
               "folds reuse those evaluations. Cumulative cost against the best log-likelihood found so far:", "")
    rows, spent, best = [], 0.0, -np.inf
    for i, (e, ll) in enumerate(zip(result.evaluations, result.loglik)):
        spent += e.wall_s
        best = max(best, ll)
        rows.append([i + 1, _point(e.values), e.rollouts, e.wall_s, spent, ll, best])
    report.table(["evaluation", "point", "rollouts", "s", "cumulative s", "log-likelihood", "best so far"], rows)
    plt = pyplot()
    _people_figure(plt, report, result, out_dir)
    _surface_figure(plt, report, result, out_dir)
    report.results = {"summary": summary_lines(result), "parameters": result.parameters,
                      "intervals": result.intervals, "mapping": result.mapping.to_dict(),
                      "cross_validated_r": result.cv.r, "reference_cross_validated_r": result.cv_reference.r,
                      "folds": [{"fold": f.fold, "chosen": result.evaluations[f.chosen].values, "r": f.fitted.r,
                                 "reference_r": f.reference.r} for f in result.folds]}
    _, md_path = report.write(out_dir)
    return md_path


def _people_figure(plt, report: Report, result: FitResult, out_dir: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    share = result.responses.yes_share
    for ax, reference in zip(axes, (False, True)):
        for f in result.folds:
            ax.scatter(f.reference_p_yes if reference else f.p_yes, share[f.test], s=12, label=f"fold {f.fold}")
        ax.plot([0, 1], [0, 1], color="0.6", lw=0.8)
        ax.set_xlabel("model P(yes), held out" + (" (reference)" if reference else " (fitted)"))
        ax.set_ylabel("people's share saying yes")
        ax.set_title(f"r = {(result.cv_reference if reference else result.cv).r:.3f}")
    axes[0].legend(fontsize=7)
    report.figure(fig, out_dir, "people", "model against people, each stimulus predicted by the fold that did not "
                                           "train on it")


def _surface_figure(plt, report: Report, result: FitResult, out_dir: Path) -> None:
    names = list(result.settings.names)
    if len(names) == 2:
        xs, ys = (sorted({e.values[n] for e in result.evaluations}) for n in names)
        surface = np.full((len(ys), len(xs)), np.nan)
        for e, ll in zip(result.evaluations, result.loglik):
            if e.values[names[0]] in xs and e.values[names[1]] in ys:
                surface[ys.index(e.values[names[1]]), xs.index(e.values[names[0]])] = ll
        fig, ax = plt.subplots(figsize=(5.5, 4.2))
        image = ax.imshow(surface - np.nanmax(surface), origin="lower", aspect="auto", cmap="viridis",
                          vmin=max(-60.0, float(np.nanmin(surface - np.nanmax(surface)))))
        ax.set_xticks(range(len(xs)), [f"{v:g}" for v in xs])
        ax.set_yticks(range(len(ys)), [f"{v:g}" for v in ys])
        ax.set_xlabel(names[0]), ax.set_ylabel(names[1])
        fig.colorbar(image, label="log-likelihood - max")
    else:
        fig, axes = plt.subplots(1, len(names), figsize=(4.5 * len(names), 3.8), squeeze=False)
        for ax, name in zip(axes[0], names):
            values, profile = result.profile(name)
            ax.plot(values, np.array(profile) - max(profile), "o-")
            ax.set_xlabel(name), ax.set_ylabel("profile log-likelihood - max")
    report.figure(fig, out_dir, "surface", "the likelihood over the grid (every stimulus, each point with its best "
                                            "mapping)")
