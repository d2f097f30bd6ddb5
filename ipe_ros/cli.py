"""``ipe``: the intuitive physics engine on the command line (no ROS needed).

    ipe predict PATH [--tower NAME ...] [--query fall,any_fall,direction,far,bump] [--samples K] [--sigma M]
                [--phi A[,A...]] [--force-direction DEG] [--mu R] [--preset NAME] [--seed N]
                [--workers W] [--ci-width W] [--deadline S] [--horizon S] [--until-rest] [--budget S] [--json] [--png FILE]
                [--no-self-check] [--verify-samples N]
    ipe ask remove|support|clear|place|push PATH ...   (questions about an action: ipe_ros/cli_ask.py)
    ipe infer OBS.json [--unknown LABEL ...] [--json] ...  (properties from observed motion: ipe_ros/cli_infer.py)
    ipe fit SCENES --responses CSV --readout R --grid NAME=V1,V2 ...  (fitted to people: ipe_ros/cli_fit.py)
    ipe generate tower --count N --seed S -o FILE [--pairs RATIO]
    ipe generate table --configurations N --seed S -o FILE
    ipe generate catalogue --count N --seed S -o FILE
    ipe generate capped-tower [--ball-speed M_S] -o FILE
    ipe generate depth-example -o DIR
    ipe generate zoo --per-family N --seed S [--families launch,dominoes,...] -o FILE
    ipe generate probe-push [--seed S] [--mass KG] [--friction MU] -o OBS.json
    ipe demo
    ipe experiment NAME|all [--quick] [--out DIR] [--data DIR] [--samples K] [--stimuli N] [--seed N]
                [--workers W] [--preset NAME] [--resamples N] [--grid-samples K]
                [--human FILE --human-scale SCALE]

Bad input ends with exit status 2 and one line on stderr naming the problem.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np

from .cli_ask import add_ask_parser, cmd_ask
from .cli_evidence import add_perception_options
from .cli_fit import add_fit_parser, cmd_fit
from .cli_infer import add_infer_parser, cmd_infer
from .cli_inputs import add_input_options, add_inputs_from_option, finite
from .cli_predict import EXIT_BAD_INPUT, add_batch_options, batch_map, cmd_predict, format_table, run_predictions, stored_line
from .cli_queries import add_query_parameter_options
from .engine import PRESETS, ConfigError, ModelConfig, Prediction, QuerySpec, Request, SceneError, load_scenes, preset
from .engine.scene.catalogue import capped_tower, scene_catalogue
from .engine.config import DEFAULT_MODEL, DEFAULT_PRESET, DEFAULT_QUERIES, default_workers
from .engine.scene.examples import example_scene_path
from .engine.scene.generators import generate_tables, generate_towers, state_pair
from .engine.inputs import as_spelled
from .engine.perceptions import perception_names, perception_source
from .engine.plugins import load_plugins
from .engine.scene.format import write_scenes
from .engine.scene.zoo import FAMILIES, scene_zoo

#: ``analysis.experiments.EXPERIMENTS`` and ``analysis.human.SCALES`` by name (tests keep them equal):
#: importing the analyses loads scipy.stats, ~1 s that every other command would pay at start.
EXPERIMENT_NAMES = ("fall", "direction", "mass", "far", "bump", "samples", "features", "vision")
HUMAN_SCALES = ("1-7", "unit", "degrees", "radians", "metres")


class _OneLineParser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # argparse prints usage + message; we want one line
        self.exit(EXIT_BAD_INPUT, f"ipe: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _OneLineParser(prog="ipe", description="Intuitive physics engine (Battaglia et al. 2013).")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_OneLineParser)

    p = sub.add_parser("predict", help="predict what will fall in a scene file (JSON or paper CSV)")
    p.add_argument("path", help="a JSON scene file or a paper-format tower CSV")
    p.add_argument("--tower", action="append", default=None, metavar="NAME",
                   help="only this scene/tower (repeatable; default: all in the file)")
    add_input_options(p, ("queries", "contact"))
    add_query_parameter_options(p)
    add_input_options(p, ("samples", "sigma_m", "phi_m_s2", "force_direction_deg", "mu", "mass_log_sd",
                          "friction_log_sd", "restitution_half_width", "launch_speed_log_sd",
                          "launch_direction_sd_deg", "perception"), notes={
        "perception": "where the k noisy scenes come from: " + "; ".join(
            f"{n}: {perception_source(n).summary}" for n in perception_names())
        + " (each with its options below); sigma unused but by gaussian"})
    add_inputs_from_option(p)
    add_perception_options(p)
    add_input_options(p, ("preset_name", "seed", "workers", "ground_truth", "ci_width", "deadline_s", "horizon_s",
                          "until_rest", "budget_s", "self_check", "verify_samples",
                          "always_verify"))
    p.add_argument("--json", action="store_true", help="one JSON object per scene per line")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the samples on a Dask cluster (e.g. tcp://10.0.0.2:8786; default: $IPE_DASK_SCHEDULER, "
                        "else worker processes here); see docs/cluster.md")
    p.add_argument("--png", default=None, metavar="FILE",
                   help="also draw the answer: the scene coloured by fall probability and three sampled rollouts "
                        "(one scene only)")

    add_ask_parser(sub, _OneLineParser)
    add_infer_parser(sub)
    add_fit_parser(sub)

    g = sub.add_parser("generate", help="write generated scenes (JSON)")
    gsub = g.add_subparsers(dest="kind", required=True, parser_class=_OneLineParser)
    t = gsub.add_parser("tower", help="paper-style 10-block towers")
    t.add_argument("--count", type=int, default=1)
    t.add_argument("--blocks", type=int, default=10)
    t.add_argument("--pairs", type=finite, default=None, metavar="RATIO",
                   help="also write a heavy/light state pair per tower with this mass ratio")
    t.add_argument("--seed", type=int, required=True)
    t.add_argument("-o", "--output", required=True)
    tb = gsub.add_parser("table", help="Exp. 5 red/yellow block configurations x five tables")
    tb.add_argument("--configurations", type=int, default=12)
    tb.add_argument("--seed", type=int, required=True)
    tb.add_argument("-o", "--output", required=True)
    cat = gsub.add_parser("catalogue", help="random scenes of mixed shapes, 5 mm to 1 m, thrown bodies (tests' catalogue)")
    cat.add_argument("--count", type=int, default=10)
    cat.add_argument("--seed", type=int, required=True)
    cat.add_argument("-o", "--output", required=True)
    cap = gsub.add_parser("capped-tower", help="three boxes, a cone on top, a ball rolled at the base (the guide's example)")
    cap.add_argument("--ball-speed", type=finite, default=5.0, metavar="M_S", help="the ball's speed (default 5 m/s)")
    cap.add_argument("-o", "--output", required=True)
    dx = gsub.add_parser("depth-example", help="the example tower seen by a depth camera: a depth PNG, camera_info "
                                               "YAML, the camera's pose and the detector's guess (for --perception depth)")
    dx.add_argument("--seed", type=int, default=0)
    dx.add_argument("-o", "--output", required=True, metavar="DIR")
    zoo = gsub.add_parser("zoo", help="the scene zoo: impacts, dominoes, ramps, drops, rings, bouncy blocks, plates, "
                                      "capped towers (docs/zoo.md)")
    zoo.add_argument("--per-family", type=int, default=4)
    zoo.add_argument("--seed", type=int, required=True)
    zoo.add_argument("--families", default=",".join(FAMILIES), help="comma-separated (default: all)")
    zoo.add_argument("-o", "--output", required=True)
    probe = gsub.add_parser("probe-push", help="an observation (ipe_ros.observation/1) of a box pushed with a known "
                                               "impulse, made at known mass and friction (for ipe infer)")
    probe.add_argument("--seed", type=int, default=0, help="the tracker noise's seed")
    probe.add_argument("--mass", type=finite, default=0.8, metavar="KG", help="the box's true mass (default 0.8 kg)")
    probe.add_argument("--friction", type=finite, default=0.45, metavar="MU",
                       help="the box's true friction on a floor of friction 1 (default 0.45)")
    probe.add_argument("-o", "--output", required=True)

    sub.add_parser("demo", help="predict on the built-in example tower (IPE and ground truth)")

    e = sub.add_parser("experiment", help="rerun one of the paper's model analyses; writes JSON, Markdown, PNG")
    e.add_argument("name", choices=[*EXPERIMENT_NAMES, "all"])
    e.add_argument("--quick", action="store_true", help="few stimuli and samples (minutes; what CI runs)")
    e.add_argument("--out", default="experiments", help="output folder (default: ./experiments)")
    e.add_argument("--data", default=None, help="the authors' stimuli (default: $IPE_SHARED_DATA or "
                                                "../shared/data/battaglia2013 beside the repository)")
    e.add_argument("--samples", type=int, default=None, help="k of the model (default 48, quick 6)")
    e.add_argument("--stimuli", type=int, default=None, help="use the first N stimuli of each set")
    e.add_argument("--grid-samples", type=int, default=None, help="k per cell of fall's sigma x phi grid")
    e.add_argument("--seed", type=int, default=0)
    add_batch_options(e)
    e.add_argument("--preset", default=DEFAULT_PRESET, choices=sorted(PRESETS))
    e.add_argument("--resamples", type=int, default=10_000, help="bootstrap resamples (paper: 10 000)")
    e.add_argument("--human", default=None, help="CSV with columns stimulus,response (people's judgments)")
    e.add_argument("--human-scale", default=None, choices=HUMAN_SCALES, help="what the responses are measured in")
    e.add_argument("--vision-resolution", type=int, default=None, metavar="PX",
                   help="vision: rendered image size (default 256, the SI's; blur and likelihood SD scale with it)")
    return parser


def cmd_generate(args) -> int:
    if args.kind == "probe-push":
        import json

        from .engine.inference.known import probe_push

        if not 0.05 <= args.mass <= 5:
            raise ConfigError("--mass", f"must be in [0.05, 5] kg (the example's prior), got {args.mass:g}")
        if not 0.05 <= args.friction <= 1.2:
            raise ConfigError("--friction", f"must be in [0.05, 1.2] (the example's prior), got {args.friction:g}")
        observation = probe_push(np.random.default_rng(args.seed), mass_kg=args.mass, friction=args.friction)
        Path(args.output).write_text(json.dumps(observation, indent=1) + "\n")
        print(f"wrote an observation of {len(observation['frames'])} frames to {args.output}", file=sys.stderr)
        return 0
    if args.kind == "depth-example":
        from .engine.vision.depth_io import write_depth_example

        paths = write_depth_example(args.output, load_scenes(example_scene_path())[0], args.seed)
        print("wrote " + ", ".join(str(p) for p in paths.values()), file=sys.stderr)
        return 0
    if args.kind == "tower":
        if args.count < 1:
            raise ConfigError("--count", f"must be >= 1, got {args.count}")
        scenes = generate_towers(args.seed, args.count, n_blocks=args.blocks)
        if args.pairs is not None:
            rng = np.random.default_rng(args.seed)
            scenes = [s for scene in scenes for s in (scene, *state_pair(scene, rng, ratio=args.pairs))]
    elif args.kind == "table":
        if args.configurations < 1:
            raise ConfigError("--configurations", f"must be >= 1, got {args.configurations}")
        scenes = generate_tables(args.seed, args.configurations)
    elif args.kind == "catalogue":
        if args.count < 1:
            raise ConfigError("--count", f"must be >= 1, got {args.count}")
        scenes = scene_catalogue(args.seed, args.count)
    elif args.kind == "zoo":
        if args.per_family < 1:
            raise ConfigError("--per-family", f"must be >= 1, got {args.per_family}")
        families = tuple(f.strip() for f in args.families.split(",") if f.strip())
        unknown = [f for f in families if f not in FAMILIES]
        if unknown or not families:
            raise ConfigError("--families", (f"unknown family {unknown[0]!r}; " if unknown else "none given; ")
                              + f"choose from {', '.join(FAMILIES)}")
        scenes = scene_zoo(args.seed, args.per_family, families)
    else:
        scenes = [capped_tower(args.ball_speed)]
    write_scenes(scenes, args.output)
    print(f"wrote {len(scenes)} scene(s) to {args.output}", file=sys.stderr)
    return 0


def cmd_demo(_args) -> int:
    scenes = load_scenes(example_scene_path())
    workers = default_workers()
    query = QuerySpec(queries=DEFAULT_QUERIES)
    print(f"Built-in example: {example_scene_path().name} ({len(scenes[0].objects)} blocks of 0.2 x 0.6 x 0.2 m)\n")
    ipe_title = (f"IPE (sigma = {DEFAULT_MODEL.sigma_m:g} m = 0.2 block short sides, phi = 0, "
                 f"k = {DEFAULT_MODEL.samples}):")
    for title, model in (("Ground truth (sigma = phi = 0, one deterministic rollout):", ModelConfig(object_noise=False)),
                         (ipe_title, DEFAULT_MODEL)):
        rows: list[Prediction] = []
        run_predictions(scenes, Request(model=model, settings=preset(DEFAULT_PRESET), query=query, budget_s=None),
                        workers, rows.append)
        print(title)
        print(format_table(rows))
        p = rows[0]
        risky = sorted(p.object_fall_probability.items(), key=lambda kv: -kv[1])[:3]
        if risky[0][1] > 0:
            print("most likely to fall: " + ", ".join(f"{n} ({v:.2f})" for n, v in risky) + "\n")
        else:
            print("no block falls\n")
    return 0


def cmd_experiment(args) -> int:
    from . import progress
    from .analysis import reporting
    from .analysis.experiments import EXPERIMENTS, Options

    reporting.use(progress.steps, progress.progress)  # bars on a terminal, lines in a log
    from .analysis.human import load_human_responses
    from .analysis.paper_data import shared_data_dir

    for name in ("samples", "stimuli", "grid_samples"):
        value = getattr(args, name)
        if value is not None and value < 1:
            raise ConfigError(f"--{name.replace('_', '-')}", f"must be >= 1, got {value}")
    if args.seed < 0:
        raise ConfigError("--seed", f"must be >= 0, got {args.seed}")
    if args.resamples < 100:
        raise ConfigError("--resamples", f"must be >= 100, got {args.resamples}")
    if args.workers < 0:
        raise ConfigError("--workers", f"must be >= 0, got {args.workers}")
    if (args.human is None) != (args.human_scale is None):
        raise ConfigError("--human-scale", "give --human FILE and --human-scale SCALE together")
    human = load_human_responses(args.human, args.human_scale) if args.human else None
    opts = Options(out_dir=Path(args.out), data_dir=Path(args.data) if args.data else shared_data_dir(),
                   quick=args.quick, seed=args.seed, samples=args.samples, stimuli=args.stimuli,
                   preset=args.preset, resamples=args.resamples, grid_samples=args.grid_samples, human=human,
                   human_path=args.human, vision_resolution=args.vision_resolution)
    names = list(EXPERIMENTS) if args.name == "all" else [args.name]
    with batch_map(args.scheduler, args.workers, args.resume) as (map_fn, store):
        for name in names:
            print(f"experiment {name}{' (quick)' if args.quick else ''} ...", file=sys.stderr, flush=True)
            report = EXPERIMENTS[name](opts, map_fn)
            if store is not None:
                print(stored_line(store, args.resume), file=sys.stderr)
            json_path, md_path = report.write(opts.out_dir)
            print(f"wrote {md_path} and {json_path}" + (f" (+{len(report.figures)} PNG)" if report.figures else ""))
    return 0


#: a comma-separated list of numbers whose first is negative ("-0.85,0.1,0.6,...")
_NEGATIVE_VECTOR = re.compile(r"^-\.?\d[^,]*,")


def glue_negative_vectors(argv: list[str]) -> list[str]:
    """argparse takes "-0.85,0.1,..." for an unknown option (only a lone negative number passes), so
    ``--camera-pose -0.85,...`` and ``--velocity -0.4,0`` failed; no option starts with a digit, so such
    a list is glued to the option before it (``--camera-pose=-0.85,...``)."""
    glued: list[str] = []
    for token in argv:
        if glued and _NEGATIVE_VECTOR.match(token) and glued[-1].startswith("--") and "=" not in glued[-1]:
            glued[-1] = f"{glued[-1]}={token}"
        else:
            glued.append(token)
    return glued


def main(argv: list[str] | None = None) -> int:
    argv = glue_negative_vectors(sys.argv[1:] if argv is None else list(argv))
    # installed packages' queries and perceptions, before the options that offer them are made
    load_plugins(lambda problem: print(f"ipe: warning: {problem}", file=sys.stderr))
    args = build_parser().parse_args(argv)
    args.argv = tuple(argv)  # which options were typed: --inputs-from fills the others
    try:
        if args.command == "predict":
            return cmd_predict(args)
        if args.command == "generate":
            return cmd_generate(args)
        if args.command == "ask":
            return cmd_ask(args)
        if args.command == "infer":
            return cmd_infer(args)
        if args.command == "experiment":
            return cmd_experiment(args)
        if args.command == "fit":
            return cmd_fit(args)
        return cmd_demo(args)
    except ConfigError as exc:  # named as the command line spells it (engine.inputs)
        print(f"ipe: error: {as_spelled(exc, 'cli')}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SceneError as exc:
        print(f"ipe: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (OSError, ValueError) as exc:
        print(f"ipe: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("ipe: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
