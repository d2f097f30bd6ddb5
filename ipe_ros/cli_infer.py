"""``ipe infer``: an observation's unknown masses, frictions and restitutions (docs/inference.md).

    ipe infer OBS.json [--unknown box.mass_kg ...] [--preset NAME] [--seed N] [--workers W] [--budget S]
              [--model-error F] [--particles N] [--rounds N] [--refined FILE] [--json]

An observation no property values reproduce is an answer (``consistent: false``, exit status 0);
bad input ends with exit status 2 and one line naming the field.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

from .cli_inputs import add_input_options, finite
from .cli_predict import sample_map
from .engine.config import preset
from .engine.errors import ConfigError
from .engine.inference.amis import AmisSettings
from .engine.inference.infer import Inference, InferSettings, infer
from .engine.inference.likelihood import MODEL_ERROR_GRID
from .engine.inference.observation import Observation, observation_from_json
from .engine.scene.format import scene_to_json
from .engine.safe_files import UnreadableFile, read_file_bounded
from .engine.scene.limits import MAX_JSON_CHARS


def add_infer_parser(sub) -> None:
    p = sub.add_parser("infer", help="unknown masses, frictions and restitutions from observed motion "
                                     "(an ipe_ros.observation/1 file)")
    p.add_argument("path", help="an ipe_ros.observation/1 JSON file (docs/inference.md)")
    p.add_argument("--unknown", action="append", default=None, metavar="LABEL",
                   help="infer only this unknown of the file (box1.mass_kg, group:red.mass_kg, support.friction; "
                        "repeatable; the others keep the scene's values)")
    add_input_options(p, ("preset_name", "seed", "workers", "budget_s"))
    p.add_argument("--model-error", type=finite, default=None, metavar="F",
                   help="the physics' own error, as a fraction of the distance an object travelled (default: inferred "
                        f"with the properties, log-uniform over {MODEL_ERROR_GRID[0]:g}..{MODEL_ERROR_GRID[-1]:g}; "
                        "docs/inference.md)")
    p.add_argument("--particles", type=int, default=AmisSettings.particles_per_round, metavar="N",
                   help=f"candidates per round (default {AmisSettings.particles_per_round})")
    p.add_argument("--rounds", type=int, default=AmisSettings.max_rounds, metavar="N",
                   help=f"the most rounds (default {AmisSettings.max_rounds}; fewer once the answer's effective "
                        f"sample size reaches {AmisSettings.target_ess:g})")
    p.add_argument("--refined", default=None, metavar="FILE",
                   help="write the scene with the posterior medians in place (for ipe predict / ipe ask)")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="write a rerun recording: the observed frames over the rollout at the posterior medians, "
                        "each unknown's posterior as a histogram")
    p.add_argument("--json", action="store_true", help="one JSON object")


def read_observation(path: str, only: list[str] | None) -> Observation:
    """The observation file's, read bounded (a link to a device, a FIFO, a folder or a file past
    ``MAX_JSON_CHARS`` refused in one line naming it), with only the ``only`` unknowns."""
    file = Path(path)
    try:
        text = read_file_bounded(file, MAX_JSON_CHARS, "an observation").decode("utf-8")
    except UnreadableFile as exc:
        raise ConfigError("observation", f"{exc}{'; send fewer frames' if exc.too_large else ''}") from None
    except UnicodeDecodeError:
        raise ConfigError("observation", f"{file}: not UTF-8 text; write the observation as JSON") from None
    observation = observation_from_json(text)
    if only:
        labels = [u.label for u in observation.unknowns]
        missing = [label for label in only if label not in labels]
        if missing:
            raise ConfigError("--unknown", f"{missing[0]!r} is not an unknown of {file.name}; it has {', '.join(labels)}")
        observation = dataclasses.replace(observation, unknowns=tuple(u for u in observation.unknowns if u.label in only))
    return observation


def format_inference(answer: Inference) -> str:
    lines = [f"{answer.scene_name}: {answer.message}"]
    if answer.consistent:
        lines.append(f"{'unknown':<28} {'median':>10} {'90% interval':>24} {'mean':>10}")
        for e in answer.estimates:
            lines.append(f"{e.label:<28} {e.median:>10.4g} {f'[{e.low_90:.4g}, {e.high_90:.4g}]':>24} {e.mean:>10.4g}")
        for pair in answer.heavier:
            lines.append(f"P({pair.a} > {pair.b}) = {pair.p_a_heavier:.3f}; ratio {pair.ratio_median:.3g} "
                         f"[{pair.ratio_low_90:.3g}, {pair.ratio_high_90:.3g}]")
    if answer.model_error is not None:
        e = answer.model_error
        lines.append(f"the physics' own error: {100 * e.median:.2g}% of the distance travelled "
                     f"[{100 * e.low_90:.2g}, {100 * e.high_90:.2g}]")
    lines.append(f"check: the best rollout's farthest frame {1000 * answer.worst_residual_m:.1f} mm "
                 f"(t = {answer.worst_t_s:g} s, {answer.worst_object}); {answer.candidates} candidates, "
                 f"{answer.failed} failed, {answer.elapsed_s:.1f} s")
    return "\n".join(lines)


def cmd_infer(args) -> int:
    observation = read_observation(args.path, args.unknown)
    settings = InferSettings(simulation=preset(args.preset_name), seed=args.seed, budget_s=args.budget_s,
                             model_error_fraction=args.model_error,
                             sampler=dataclasses.replace(AmisSettings(), particles_per_round=args.particles,
                                                         max_rounds=args.rounds))
    pool = sample_map(None, args.workers)
    try:
        answer = infer(observation, settings, pool.map if pool else None)
    finally:
        if pool is not None:
            pool.close()
    if args.refined and answer.refined_scene is not None:
        Path(args.refined).write_text(scene_to_json(answer.refined_scene, indent=1) + "\n")
    if args.rrd:
        from .viz.inference_log import write_inference_rrd

        write_inference_rrd(args.rrd, observation, answer)
    if args.json:
        print(json.dumps(answer.to_dict()))
    else:
        print(format_inference(answer))
    sys.stdout.flush()
    return 0
