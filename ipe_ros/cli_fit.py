"""``ipe fit``: the IPE's free inputs fitted to people's responses (ipe_ros/analysis/fitting).

    ipe fit SCENES --responses CSV --readout 'contact_probability["target:zone"]'
            --grid sigma=0,0.02,0.04 --grid launch_direction_sd_deg=0,10,20 [--reference sigma=0.04]
            [--fix NAME=VALUE ...] [--samples K] [--folds 5] [--seed N] [--preset NAME] [--workers W]
            [--resume DIR] [-o FIT.json] [--report DIR]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .cli_inputs import float_list
from .cli_predict import add_batch_options, batch_map, stored_line
from .engine import PRESETS, ConfigError, load_scenes
from .engine.config import DEFAULT_PRESET
from .engine.input_sets import MODEL_INPUTS, model_input


def _assignment(kind):
    def parse(text: str):
        name, sep, value = text.partition("=")
        if not sep or not name.strip():
            raise argparse.ArgumentTypeError(f"write NAME=VALUE (NAME one of {', '.join(MODEL_INPUTS)}), got {text!r}")
        return name.strip(), kind(value)
    return parse


def _one(text: str) -> float:
    values = float_list(text)
    if len(values) != 1:
        raise argparse.ArgumentTypeError(f"expected one number, got {text!r}")
    return values[0]


def add_fit_parser(sub) -> None:
    f = sub.add_parser("fit", help="fit the model's inputs to people's responses (cross-validated); writes a "
                                   "parameter set that ipe predict/ask --inputs-from and the node load")
    f.add_argument("path", help="the stimuli: a JSON scene file")
    f.add_argument("--responses", required=True, metavar="CSV",
                   help="people's responses: one row per stimulus with its name, share saying yes, responders")
    f.add_argument("--share-column", default="people_p_yes")
    f.add_argument("--responders-column", default="responders")
    f.add_argument("--truth-column", default="hit_zone", help="the true outcome, 0/1 (optional: accuracy)")
    f.add_argument("--readout", required=True,
                   help='the answer\'s number that is the model\'s P(yes): FIELD or FIELD["KEY"], e.g. '
                        'contact_probability["target:zone"], object_fall_probability["target"], any_fall_probability')
    f.add_argument("--grid", action="append", type=_assignment(float_list), required=True, metavar="NAME=V1,V2,...",
                   help=f"a parameter to fit and the values to try (repeatable; {', '.join(MODEL_INPUTS)})")
    f.add_argument("--reference", action="append", type=_assignment(_one), default=[], metavar="NAME=V",
                   help="the point the fit is held against (default: each input's default: the paper's sigma "
                        "0.04 m, no other noise)")
    f.add_argument("--fix", action="append", type=_assignment(_one), default=[], metavar="NAME=V",
                   help="an input held at a value during the fit (and written to the parameter set)")
    f.add_argument("--samples", type=int, default=16, help="k per stimulus and grid point (default 16)")
    f.add_argument("--folds", type=int, default=5, help="cross-validation folds (default 5)")
    f.add_argument("--seed", type=int, default=0, help="the samples' and the folds' seed")
    f.add_argument("--stimuli", type=int, default=None, help="only the first N stimuli with responses")
    f.add_argument("--preset", default=DEFAULT_PRESET, choices=sorted(PRESETS))
    add_batch_options(f)
    f.add_argument("-o", "--output", default="fit.json", help="the parameter set (default fit.json)")
    f.add_argument("--report", default=None, metavar="DIR", help="also write DIR/fit.md with its figures")


#: the fit's own fields, which its errors name: spelled as the options here
_OPTIONS = ("grid", "folds", "reference", "readout", "responses", "fix")


def cmd_fit(args) -> int:
    try:
        return _fit(args)
    except ConfigError as exc:
        if exc.field in _OPTIONS:
            raise ConfigError(f"--{exc.field}", exc.problem) from None
        raise


def _fit(args) -> int:
    from . import progress
    from .analysis import reporting
    from .analysis.fitting.fit import fit, parameter_set, write_parameter_set
    from .analysis.fitting.page import summary_lines, write_page
    from .analysis.fitting.readout import parse_readout
    from .analysis.fitting.responses import Columns, load_responses, matched

    reporting.use(progress.steps, progress.progress)
    for name in ("samples", "folds"):
        if getattr(args, name) < 1:
            raise ConfigError(f"--{name}", f"must be >= 1, got {getattr(args, name)}")
    if args.stimuli is not None and args.stimuli < 2:
        raise ConfigError("--stimuli", f"must be >= 2, got {args.stimuli}")
    readout = parse_readout(args.readout)
    grid = dict(args.grid)
    if len(grid) != len(args.grid):
        raise ConfigError("--grid", "a parameter is given twice: give each once")
    for name, _ in [*args.grid, *args.reference, *args.fix]:
        model_input(name)
    responses = load_responses(args.responses, Columns(share=args.share_column, responders=args.responders_column,
                                                       truth=args.truth_column))
    scenes = load_scenes(args.path)
    responses = matched(responses, [s.name for s in scenes])
    answered = set(responses.stimuli)
    scenes = [s for s in scenes if s.name in answered]
    if args.stimuli is not None:
        scenes = scenes[:args.stimuli]
        responses = responses.subset([s.name for s in scenes])
    reference = {name: float(model_input(name).default or 0.0) for name in grid} | dict(args.reference)
    with batch_map(args.scheduler, args.workers, args.resume) as (map_fn, store):
        result = fit(scenes, responses, readout, grid, reference=reference, fixed=dict(args.fix), samples=args.samples,
                     seed=args.seed, folds=args.folds, preset_name=args.preset, map_fn=map_fn)
    if store is not None:
        print(stored_line(store, args.resume), file=sys.stderr)
    print("\n".join(summary_lines(result)))
    write_parameter_set(args.output, parameter_set(result, scenes_path=str(args.path), responses_path=str(args.responses)))
    print(f"wrote {args.output}")
    if args.report is not None:
        md = write_page(result, Path(args.report), {"scenes": args.path, "responses": args.responses,
                                                    "readout": str(readout), "samples": args.samples,
                                                    "folds": args.folds, "seed": args.seed, "preset": args.preset})
        print(f"wrote {md}")
    return 0
