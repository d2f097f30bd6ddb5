"""``ipe ask``: questions about the robot's next action, on the command line.

    ipe ask remove PATH [--object NAME ...]            P(anything else falls) without each object
    ipe ask support PATH [--threshold P] [--safe-below P] [--png FILE]   the support graph, safe set
    ipe ask clear PATH [--target NAME]                  an order to take the scene apart, each step's risk
    ipe ask place PATH --object JSON (--at X,Y[,YAW_DEG] ... | --region X0,X1,Y0,Y1 [--yaw A0,A1 --yaws N]
                       [--candidates N])               where to put a new object
    ipe ask push PATH --object NAME --velocity VX,VY [--point X,Y,Z] [--direction-sigma-deg D]
                      [--speed-sigma F]                 what a push makes fall, and where

Common options: --scene NAME (a file holding several), --samples K (default 16), --sigma M, --preset,
--seed, --workers, --budget S, --self-check, --verify-samples N, --json (one JSON object per line).
See ipe_ros.engine.actions.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from .engine import ConfigError, WorkerPool, load_scenes
from .engine import actions as A
from .engine.inputs import as_spelled
from .engine.request import build_request
from .cli_evidence import add_perception_options, asked_source, describe_perceived, perceive_for_question
from .cli_inputs import add_input_options, add_inputs_from_option, finite, given_request_arguments
from .cli_queries import add_query_parameter_options, given_query_parameters
from .engine.actions.answers import QUESTION_QUERIES
from .engine.query import QUERIES, parse_queries

#: Samples per variant: a question has many variants, and common random numbers make k = 16 enough
#: to rank them (the paper's k = 48 is for one judgment).
DEFAULT_ASK_SAMPLES = 16


def _numbers(count: tuple[int, ...], name: str):
    def parse(text: str) -> tuple[float, ...]:
        try:
            values = tuple(float(v) for v in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected numbers separated by commas, got {text!r}") from None
        if len(values) not in count or not all(math.isfinite(v) for v in values):
            raise argparse.ArgumentTypeError(f"{name}: expected {' or '.join(map(str, count))} finite numbers, "
                                             f"got {text!r}")
        return values
    return parse


def _query_names(text: str) -> tuple[str, ...]:
    """argparse type of ipe ask's --query: registered query names, in the order given."""
    names = tuple(dict.fromkeys(part.strip() for part in text.split(",") if part.strip()))
    try:
        parse_queries(",".join(names))
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(exc.problem) from None
    return names


def add_ask_parser(sub, one_line_parser) -> None:
    ask = sub.add_parser("ask", help="questions about an action: remove, support, clear, place, push")
    questions = ask.add_subparsers(dest="question", required=True, parser_class=one_line_parser)

    def common(q):
        q.add_argument("path", help="a JSON scene file (or a paper-format tower CSV)")
        q.add_argument("--scene", default=None, metavar="NAME", help="which scene of the file (default: the only one)")
        add_input_options(q, ("samples", "sigma_m", "mass_log_sd", "friction_log_sd", "restitution_half_width",
                              "launch_speed_log_sd", "launch_direction_sd_deg",
                              "ground_truth", "preset_name", "seed", "workers", "budget_s", "fell_off", "self_check",
                              "verify_samples"),
                          defaults={"samples": DEFAULT_ASK_SAMPLES, "self_check": False},
                          notes={"samples": "samples per variant",
                                 "ground_truth": "no noise at all (sigma = 0, no body's own noise; a push with noise "
                                                 "of its own is refused): one rollout per variant",
                                 "budget_s": "compute budget per batch of variants, seconds",
                                 "fell_off": "also which objects end off the table (a scene on a table)",
                                 "self_check": "check every variant's fast physics against the converged reference "
                                               "and answer a contradicted one at the reference (docs/model.md, "
                                               "'Self-checking answers'); costs 1.5-6x the question's time; without "
                                               "it each variant says fidelity: unverified",
                                 "verify_samples": "samples of each variant rerun at the reference to verify it"})
        add_inputs_from_option(q)
        q.add_argument("--fixed-k", action="store_true",
                       help="every variant runs all --samples (default: decision questions sample until decided)")
        add_perception_options(q, evidence_only=True)  # a perception's evidence: its posterior's scenes replace --sigma
        q.add_argument("--json", action="store_true", help="one JSON object per line")
        q.add_argument("--rrd", default=None, metavar="FILE",
                       help="record 4 rollouts of every variant to this rerun file (not for clear)")

    def contact(q):
        add_input_options(q, ("contact",), notes={"contact": "also P(A touches B) per variant (repeatable; B may "
                                                             "be 'support')"})
        q.add_argument("--query", type=_query_names, default=(), metavar="NAMES",
                       help="also these queries per variant, comma-separated (registered ones beyond what the "
                            "question answers itself: " + ", ".join(n for n in QUERIES if n not in QUESTION_QUERIES)
                            + "; docs/model.md)")
        add_query_parameter_options(q)

    r = questions.add_parser("remove", help="P(anything else falls) if an object is taken away")
    common(r)
    contact(r)
    r.add_argument("--object", action="append", default=None, metavar="NAME", help="repeatable; default: every object")
    r.add_argument("--safe-below", type=finite, default=None, metavar="P",
                   help="decide each removal safe or unsafe at this P(anything falls), sampling until decided")
    r.add_argument("--what-falls", action="store_true",
                   help="with --safe-below: also which objects fall (otherwise each rollout ends at its first fall)")
    s = questions.add_parser("support", help="which objects hold which up, and what is safe to remove now")
    common(s)
    s.add_argument("--threshold", type=finite, default=A.DEFAULT_SUPPORT_THRESHOLD)
    s.add_argument("--safe-below", type=finite, default=A.DEFAULT_SAFE_BELOW)
    s.add_argument("--png", default=None, metavar="FILE", help="also draw the graph over a side view of the scene")
    c = questions.add_parser("clear", help="an order that takes the scene apart (or down to a target)")
    common(c)
    c.add_argument("--target", default=None, metavar="NAME")
    p = questions.add_parser("place", help="how risky it is to put a new object here, or where it is safest")
    common(p)
    contact(p)
    p.add_argument("--object", required=True, metavar="JSON", help="the new object in the scene format (/2)")
    p.add_argument("--at", action="append", type=_numbers((2, 3), "--at"), default=None, metavar="X,Y[,YAW_DEG]",
                   help="a candidate spot (repeatable); the object is lowered onto what is below")
    p.add_argument("--region", type=_numbers((4,), "--region"), default=None, metavar="X0,X1,Y0,Y1",
                   help="search this rectangle for the safest spots")
    p.add_argument("--yaw", type=_numbers((2,), "--yaw"), default=(0.0, 0.0), metavar="A0,A1",
                   help="yaw range in degrees for --region")
    p.add_argument("--yaws", type=int, default=1, help="yaw values tried in the range")
    p.add_argument("--candidates", type=int, default=16, help="spots on the --region grid")
    p.add_argument("--what-falls", action="store_true",
                   help="also which objects fall (otherwise each rollout ends at its first fall)")
    u = questions.add_parser("push", help="what falls when an object is pushed")
    common(u)
    contact(u)
    u.add_argument("--object", required=True, metavar="NAME")
    u.add_argument("--velocity", required=True, type=_numbers((2,), "--velocity"), metavar="VX,VY",
                   help="the velocity the push gives, m/s (horizontal)")
    u.add_argument("--point", type=_numbers((3,), "--point"), default=None, metavar="X,Y,Z",
                   help="where it is pushed (scene frame); default: its centre of mass")
    u.add_argument("--direction-sigma-deg", type=finite, default=0.0)
    u.add_argument("--speed-sigma", type=finite, default=0.0, help="SD of the speed, as a fraction of it")


def _scene(args):
    scenes = load_scenes(args.path, towers=None if args.scene is None else [args.scene])
    if len(scenes) != 1:
        raise ConfigError("--scene", f"{args.path} holds {len(scenes)} scenes; name one with --scene")
    return scenes[0]


def _table(answers: A.Answers) -> str:
    """One line per variant: over all samples, then over those in which the scene stands as it is."""
    lines = [f"{'variant':<32} {'P(any falls)':>12} {'95% interval':>15} {'k':>4} {'| stands as is':>14} "
             f"{'k':>4}  most likely to fall"]
    for v in answers.variants:
        p = "-" if v.any_fall_probability is None else f"{v.any_fall_probability:.3f}"
        ci = "-" if v.any_fall_probability_ci95 is None else "[{:.2f}, {:.2f}]".format(*v.any_fall_probability_ci95)
        given = v.given_stands
        g = "-" if given is None or given.any_fall_probability is None else f"{given.any_fall_probability:.3f}"
        if v.object_fall_probability is None:
            shown = "(not asked: --what-falls)"
        else:
            worst = sorted(v.object_fall_probability.items(), key=lambda kv: -kv[1])[:3]
            shown = ", ".join(f"{n} {q:.2f}" for n, q in worst if q > 0) or "-"
        if v.any_fell_off_probability is not None:
            shown += f"; P(any falls off) {v.any_fell_off_probability:.2f}"
        note = "" if v.simulated else "  (nothing within its reach: not simulated)"
        if v.stopped_by is not None:
            note += f"  [{v.decision or 'undecided'}: {v.stopped_by} after {v.samples_drawn} samples drawn]"
        if v.fidelity not in (None, "verified", "validated"):  # escalated: the reference's answer; contradicted: do not act on it
            why = (v.self_check or {}).get("escalated_because", ())
            note += f"  ({v.fidelity}{': ' + ', '.join(why) if why else ''})"
        for key, q in (v.contact_probability or {}).items():
            note += f"; P({key.replace(':', ' touches ')}) {q:.2f}"
        lines.append(f"{v.label:<32} {p:>12} {ci:>15} {v.samples:>4} {g:>14} "
                     f"{'-' if given is None else given.samples:>4}  {shown}{note}")
    if answers.alone is not None and answers.alone.unstable:
        lines.append(f"the scene is unstable as it is: it falls by itself with P {answers.alone.any_fall_probability:.2f}"
                     f"; '| stands as is' counts only the {answers.alone.samples_standing} samples in which it stood")
    return "\n".join(lines)


def cmd_ask(args) -> int:
    scene = _scene(args)
    if args.samples < 1:
        raise ConfigError("--samples", f"must be >= 1, got {args.samples}")
    # the model and settings as ipe predict builds them (engine.request)
    request = build_request(**given_request_arguments(args))
    model, settings = request.model, request.settings
    if args.workers < 0:
        raise ConfigError("--workers", f"must be >= 0, got {args.workers}")
    pool = WorkerPool(min(args.workers, args.samples)) if args.workers > 0 else None
    kw = dict(seed=args.seed, map_fn=pool.map if pool else None, budget_s=args.budget_s, check=request.check)
    source = asked_source(args)
    if source is not None:  # every variant's sample i starts from the posterior's scene i
        perceived, chosen = perceive_for_question(args, scene, source)
        kw.update(perceived=perceived, budget_s=args.budget_s)  # the budget the chain left
        written = chosen.record(scene, perceived, model)
        if written is not None:
            print(f"wrote {written}", file=sys.stderr)
    if args.rrd:
        kw.update(record_every=max(1, round(0.02 / settings.time_step_s)), record_samples=4)
    try:
        return _answer(args, scene, model, settings, kw)
    except ConfigError as exc:  # named as the command line spells it
        raise as_spelled(question_flag(exc), "cli") from None
    finally:
        if pool is not None:
            pool.close()


def _answer(args, scene, model, settings, kw) -> int:
    question = question_from_args(args)
    reply = question.answer(scene, model, settings, **kw)
    perceived = kw.get("perceived")
    if args.json:
        data = reply.data if perceived is None else {**reply.data, "perception": perceived.to_dict()}
        print(json.dumps(data, allow_nan=False, sort_keys=True), flush=True)
    else:
        print(TEXT[question.kind](reply))
        if perceived is not None:
            source = asked_source(args)
            print(f"{source.name}: {describe_perceived(source, perceived)} for {len(perceived.scenes)} samples "
                  "(sigma unused)")
    if question.kind == "support" and args.png:
        draw_support_graph(scene, reply.result, args.png)
    if args.rrd and reply.answers is not None:
        from .viz import rerun_log

        rerun_log.write_question_rrd(args.rrd, scene, reply.answers)
    return 0


#: a question's JSON fields (engine.actions.question) as ``ipe ask`` spells them
QUESTION_FLAGS = {"objects": "--object", "object": "--object", "safe_below": "--safe-below",
                  "threshold": "--threshold", "target": "--target", "what_falls": "--what-falls",
                  "fell_off": "--fell-off", "at": "--at", "region": "--region", "region.candidates": "--candidates",
                  "region.yaws": "--yaws", "candidates": "--candidates", "yaws": "--yaws", "yaw_deg": "--yaw",
                  "velocity_m_s": "--velocity", "point_m": "--point", "direction_sigma_deg": "--direction-sigma-deg",
                  "speed_sigma": "--speed-sigma", "contact": "--contact"}


def question_flag(exc: ConfigError) -> ConfigError:
    """The error naming the ``ipe ask`` option for a question field it names (``actions[0].``-prefixed
    fields too: the CLI's question has one action)."""
    if exc.field.startswith("actions[") and "]." in exc.field:
        field = exc.field.split("].", 1)[1]
        field = "object" if field == "name" else field  # the pushed object's name
    else:
        field = exc.field
    return ConfigError(QUESTION_FLAGS[field], exc.problem) if field in QUESTION_FLAGS else exc


def question_from_args(args) -> A.Question:
    """The question the options ask, as the node would read it from JSON (engine.actions.question)."""
    common = dict(fell_off=args.fell_off, sequential=not args.fixed_k, self_check=args.self_check)
    contact = tuple(getattr(args, "contact", None) or ())
    if getattr(args, "query", ()):
        common.update(queries=tuple(args.query), query_parameters=tuple(given_query_parameters(args).items()))
    if args.question == "remove":
        return A.RemoveQuestion(objects=None if args.object is None else tuple(args.object), safe_below=args.safe_below,
                                what_falls=args.what_falls or None, contact=contact, **common)  # None: remove's default
    if args.question == "support":
        return A.SupportQuestion(threshold=args.threshold, safe_below=args.safe_below, **common)
    if args.question == "clear":
        return A.ClearQuestion(target=args.target, **common)
    if args.question == "push":
        point = None if args.point is None else tuple(args.point)
        action = A.Push(args.object, (args.velocity[0], args.velocity[1], 0.0), point,
                        math.radians(args.direction_sigma_deg), args.speed_sigma)
        return A.PushQuestion(push=action, contact=contact, **common)
    try:
        data = json.loads(args.object)
    except json.JSONDecodeError as exc:
        raise ConfigError("--object", f"not JSON ({exc.msg} at column {exc.colno})") from None
    body = A.new_object_from_dict(data, "--object")
    if (args.at is None) == (args.region is None):
        raise ConfigError("--at", "give candidate spots with --at, or a --region to search (not both)")
    place = dict(body=body, what_falls=args.what_falls, contact=contact, **common)
    if args.region is not None:
        x0, x1, y0, y1 = args.region
        region = A.Region((x0, x1), (y0, y1), (math.radians(args.yaw[0]), math.radians(args.yaw[1])))
        return A.PlaceQuestion(region=region, candidates=args.candidates, yaws=args.yaws, **place)
    spots = tuple((s[0], s[1], math.radians(s[2]) if len(s) == 3 else 0.0) for s in args.at)
    return A.PlaceQuestion(spots=spots, **place)


def _support_text(reply: A.Reply) -> str:
    graph = reply.result
    return "\n".join([
        _table(graph.answers),
        "supports (remover -> falls, P): " + (", ".join(f"{a} -> {b} {p:.2f}" for a, b, p in graph.edges) or "none"),
        "safe to remove now: " + (", ".join(f"{n} (P {p:.2f}, <= {hi:.2f})" for n, p, hi in graph.safe) or "none")])


def _clear_text(reply: A.Reply) -> str:
    order = reply.result
    lines = [f"{i:>3}. remove {step.name:<24} P(anything falls) {step.p_anything_falls:.3f} "
             f"[{step.ci95[0]:.2f}, {step.ci95[1]:.2f}]" for i, step in enumerate(order.steps, 1)]
    return "\n".join(lines + [f"total risk: {order.total_risk:.3f}"])


def _place_text(reply: A.Reply) -> str:
    lines = [f"{'x m':>8} {'y m':>8} {'z m':>8} {'yaw deg':>8} {'P(any falls)':>12} {'95% interval':>15} {'k':>4}"]
    for b, v in reply.result:
        yaw = math.degrees(2 * math.atan2(b.orientation_xyzw[2], b.orientation_xyzw[3]))
        p = "-" if v.any_fall_probability is None else f"{v.any_fall_probability:.3f}"
        ci = "-" if v.any_fall_probability_ci95 is None else "[{:.2f}, {:.2f}]".format(*v.any_fall_probability_ci95)
        decided = "" if v.decision is None else f"  {v.decision}"
        lines.append(f"{b.position_m[0]:>8.3f} {b.position_m[1]:>8.3f} {b.position_m[2]:>8.3f} {yaw:>8.1f} {p:>12} "
                     f"{ci:>15} {v.samples:>4}{decided}")
    return "\n".join(lines)


def _push_text(reply: A.Reply) -> str:
    d = reply.answers.variants[1].direction_rad
    return _table(reply.answers) + f"\nfall direction: {'-' if d is None else f'{math.degrees(d):.0f} deg'}"


#: each kind's reply as terminal lines (``--json`` prints the reply the node publishes instead)
TEXT = {"remove": lambda reply: _table(reply.answers), "support": _support_text, "clear": _clear_text,
        "place": _place_text, "push": _push_text}


def draw_support_graph(scene, graph: A.SupportGraph, path: str) -> None:
    """A side view (x-z) of the objects' bounding boxes with an arrow from each supporter to what
    falls without it, coloured by the probability; safe-to-remove objects outlined in green."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    from .engine.scene.bodies import lowest_z_m

    fig, ax = plt.subplots(figsize=(6, 5))
    centres = {}
    safe = {n for n, _, _ in graph.safe}
    for b in scene.objects:
        c = b.centre_of_mass_m
        low = lowest_z_m(b)
        half_x = max(b.extents_m) / 2 if b.static else b.extents_m[0] / 2
        height = 2 * (c[2] - low)
        ax.add_patch(Rectangle((c[0] - half_x, low), 2 * half_x, height, fill=False,
                               edgecolor="green" if b.name in safe else "black", linewidth=2 if b.name in safe else 1))
        ax.text(c[0], c[2], b.name, ha="center", va="center", fontsize=7)
        centres[b.name] = c
    cmap = plt.get_cmap("RdYlGn_r")
    for supporter, supported, p in graph.edges:
        a, b = centres[supporter], centres[supported]
        ax.annotate("", xy=(b[0], b[2]), xytext=(a[0], a[2]),
                    arrowprops=dict(arrowstyle="->", color=cmap(p), linewidth=1.5 + 2 * p))
    ax.axhline(scene.support.top_m, color="grey")
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_title(f"{scene.name}: who holds whom up (arrows: removing the tail drops the head)", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
