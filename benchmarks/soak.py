"""Soak: ``ipe_node`` as its own process under mixed good, bad and flooding input for a long while.

    .venv/bin/python benchmarks/soak.py [--minutes 30] [--out benchmarks/results/soak]

Every second or so the driver sends one of: a good scene (the example tower, the capped tower, a
catalogue scene) on ``~/scene_json`` or ``~/scene``; a bad one (malformed or deeply nested JSON, a
lone-surrogate name, a 1 MB list, NaN poses, 1e15 m positions, gravity 1e8, a 1e-9 m box, a marker
of 1e-320 m); a question on ``~/ask`` (support, remove, push, place about the newest scene) or a
hostile one (400 x 400 placements, 100,000 spots, a push 1e6 m away, 2 MB of padding, an unknown
field, malformed JSON); a scene or a question holding a mesh (``--meshes`` distinct procedural
tori under the node's ``mesh_roots``, the first time new to its cache, then cached; one too slow for
its ``mesh_decomposition_s``, refused and then remembered); or a flood (20 scenes back to back, of
which only the newest should be answered, or 200 questions, each of which must get exactly one reply).
Each good scene has a unique name, so its answer on ``~/prediction`` gives its latency (send to
answer). The node's resident memory (itself and its worker processes, from /proc) is sampled every
10 s, and so is the disk its mesh cache uses. At the end the node gets SIGINT; the time it takes to exit and whether any process is left
are recorded. Results: JSON and Markdown in ``--out``. DDS stays on loopback.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import random
import signal
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from ipe_ros.engine import load_scenes  # noqa: E402
from ipe_ros.engine.scene.catalogue import capped_tower, scene_catalogue  # noqa: E402
from ipe_ros.engine.scene.examples import example_scene_path  # noqa: E402
from ipe_ros.engine.scene.format import scene_to_dict, scene_to_json  # noqa: E402
from ipe_ros.ros.node import ASK_QOS, LATCHED_QOS  # noqa: E402
from msg_bridge.markers import scene_to_markers  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


#: What the driver sends each second or so: each kind up to its share of the draw.
MIX = (("good", 0.40), ("meshes", 0.47), ("bad", 0.65), ("questions", 0.78), ("hostile_questions", 0.9),
       ("flood", 0.95), ("question_floods", 1.0))
#: the mesh too slow to decompose within the soak node's mesh_decomposition_s (~25 s here)
SLOW_MESH_SECTIONS = 180
MESH_DECOMPOSITION_S = 10.0


def _mesh_files(folder: Path, count: int, rng: random.Random) -> list[tuple[Path, float]]:
    """``count`` distinct tori (1-4 s each to decompose here) and one too slow to, as OBJ files in
    ``folder``: (file, minor radius)."""
    import trimesh

    folder.mkdir(parents=True, exist_ok=True)
    files = []
    for i in range(count + 1):
        sections = SLOW_MESH_SECTIONS if i == count else rng.randrange(16, 48, 2)
        minor = round(rng.uniform(0.01, 0.02), 4)
        torus = trimesh.creation.torus(round(rng.uniform(0.04, 0.08), 4), minor, major_sections=sections,
                                       minor_sections=max(8, sections // 2))
        file = folder / f"torus_{i}.obj"
        torus.export(file)
        files.append((file, minor))
    return files


def _mesh_scene(name: str, file: Path, minor_m: float) -> dict:
    """A torus lying on the floor and a block beside it."""
    body = {"position_m": [0.0, 0.0, minor_m], "orientation_xyzw": [0.0, 0.0, 0.0, 1.0], "mass_kg": 0.2,
            "friction": 0.6, "restitution": 0.0, "group": "", "static": False}
    return {"format": "ipe_ros.scene/2", "name": name, "gravity_m_s2": [0.0, 0.0, -9.81],
            "support": {"type": "floor", "height_m": 0.0, "friction": 0.6, "restitution": 0.0},
            "objects": [{"name": "torus", "shape": {"type": "mesh", "uri": str(file)}, **body},
                        {"name": "block", "shape": {"type": "box", "extents_m": [0.1, 0.1, 0.1]},
                         **body, "position_m": [0.3, 0.0, 0.05]}]}


def _disk_mb(*folders: Path) -> float:
    return sum(f.stat().st_size for folder in folders if folder.is_dir() for f in folder.rglob("*") if f.is_file()) / 2**20


def _family(pid: int) -> list[int]:
    """pid and all its descendants, from /proc."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            children.setdefault(int(stat[stat.rfind(")") + 2:].split()[1]), []).append(int(entry.name))
    found, todo = [pid], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def _stop(node: subprocess.Popen) -> int:
    """SIGINT the node, kill it (our own child, by its pid) if it is not gone in 30 s; its exit code."""
    node.send_signal(signal.SIGINT)
    try:
        return node.wait(timeout=30)
    except subprocess.TimeoutExpired:
        node.kill()
        return node.wait()


@contextlib.contextmanager
def _ended_on_error(node: subprocess.Popen):
    """End the node when the driver fails before stopping it itself."""
    try:
        yield
    except BaseException:
        _stop(node)
        raise


def _rss_mb(pids: list[int]) -> float:
    total = 0
    for pid in pids:
        try:
            for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1])
        except OSError:
            pass
    return total / 1024


def _bad_inputs(tower) -> list[tuple[str, object]]:
    base = scene_to_dict(tower)

    def changed(**fields):
        scene = json.loads(json.dumps(base))
        for path, value in fields.items():
            node = scene
            keys = path.split(".")
            for key in keys[:-1]:
                node = node[int(key)] if key.isdigit() else node[key]
            node[keys[-1]] = value
        return String(data=json.dumps(scene))

    nan_markers = scene_to_markers(tower, "world")
    nan_markers.markers[1].pose.position.x = float("nan")
    tiny_marker = scene_to_markers(tower, "world")
    tiny_marker.markers[1].scale.x = 1e-320
    return [
        ("json", String(data='{"format": "ipe_ros.scene/2", "objects": [')),
        ("json", String(data="[" * 5000 + "]" * 5000)),
        ("json", changed(name="\ud800")),
        ("json", changed(**{"objects.0.shape.extents_m": [0.1] * 100_000})),
        ("json", changed(**{"objects.0.position_m": [1e15, 0.0, 0.1]})),
        ("json", changed(gravity_m_s2=[0.0, 0.0, -1e8])),
        ("json", changed(**{"objects.0.shape.extents_m": [1e-9, 1e-9, 1e-9]})),
        ("markers", nan_markers),
        ("markers", tiny_marker),
    ]


def _questions() -> tuple[list[dict], list[dict]]:
    """Good questions (about the node's newest scene) and hostile ones, without ids."""
    cube = {"name": "new", "shape": {"type": "box", "extents_m": [0.1, 0.1, 0.1]}, "mass_kg": 1.0, "friction": 0.5,
            "restitution": 0.0}
    good = [{"question": "support", "samples": 4}, {"question": "remove", "objects": ["block0"], "samples": 4},
            {"question": "push", "object": "block9", "velocity_m_s": [1.0, 0.0], "samples": 4},
            {"question": "place", "object": cube, "at": [[1.0, 0.0], [1.2, 0.3]], "samples": 4}]
    hostile = [{"question": "place", "object": cube, "region": {"x_m": [-1, 1], "y_m": [-1, 1], "candidates": 400,
                                                                 "yaws": 400}},
               {"question": "place", "object": cube, "at": [[1.0 + 1e-4 * i, 0.0] for i in range(100_000)]},
               {"question": "push", "object": "block9", "velocity_m_s": [1.0, 0.0], "point_m": [1e6, 0, 1e6]},
               {"question": "support", "padding": "x" * 2_000_000}, {"question": "support", "sampels": 4},
               {"question": "fly"}]
    return good, hostile


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--out", default=str(REPO / "benchmarks/results/soak"))
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--only", choices=[k for k, _ in MIX], default=None,
                        help="send only this kind of input, at the same pace (which input makes memory grow?)")
    parser.add_argument("--question-kinds", default=None,
                        help="ask only these kinds of good question (comma-separated, of support,remove,push,place)")
    parser.add_argument("--settle-s", type=float, default=15.0, help="wait for the last answers before SIGINT")
    parser.add_argument("--meshes", type=int, default=8, help="distinct mesh files the mesh scenes cycle through")
    parser.add_argument("--memray", default=None, metavar="FILE",
                        help="run the node under memray (native stacks) into FILE: what holds the memory it gains "
                             "(`python -m memray flamegraph --leaks FILE`; pip install memray)")
    args = parser.parse_args()
    good_questions, hostile_questions = _questions()
    if args.question_kinds:
        kinds = set(args.question_kinds.split(","))
        good_questions = [q for q in good_questions if q["question"] in kinds]
        if not good_questions:
            raise SystemExit(f"--question-kinds: none of {sorted(kinds)} is a good question's kind")
    rng = random.Random(args.seed)
    domain = 150 + os.getpid() % 80
    out = Path(args.out)
    work = Path(tempfile.mkdtemp(prefix="ipe_soak_"))  # the node's meshes and its mesh cache, new each run
    meshes = _mesh_files(work / "meshes", args.meshes, rng)
    cache = work / "cache"
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain),
               IPE_CACHE_DIR=str(cache))
    traced = [] if args.memray is None else ["-m", "memray", "run", "--native", "--force", "-o", args.memray]
    node = subprocess.Popen([sys.executable, *traced, "-m", "ipe_ros.ros.node", "--ros-args", "-p", "workers:=2",
                             "-p", "samples:=8", "-p", "budget_s:=10.0", "-p", f"mesh_roots:={work / 'meshes'}",
                             "-p", f"mesh_decomposition_s:={MESH_DECOMPOSITION_S}", "--log-level", "warn"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with _ended_on_error(node):  # the node must not outlive a driver that fails
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        client = rclpy.create_node("ipe_soak_driver", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(client)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()

        sent_at: dict[str, float] = {}
        latencies: list[float] = []
        answers = {"ok": 0, "error": 0, "budget": 0, "decomposing": 0}
        diagnostics: list[dict] = []
        lock = threading.Lock()

        def on_answer(msg: String) -> None:
            data = json.loads(msg.data)
            with lock:
                if "decomposing" in data:  # its answer (or refusal) follows once the mesh is decomposed
                    answers["decomposing"] += 1
                    return
                if "error" in data:
                    answers["error"] += 1
                    sent_at.pop(data.get("scene_id"), None)
                    return
                answers["ok"] += 1
                answers["budget"] += data.get("stopped_by") == "budget"
                start = sent_at.pop(data.get("scene_id"), None)
                if start is not None:
                    latencies.append(time.monotonic() - start)

        def on_diagnostics(msg: DiagnosticArray) -> None:
            if msg.status and msg.status[0].name.startswith("/ipe"):
                with lock:
                    diagnostics[:] = [{kv.key: kv.value for kv in msg.status[0].values}
                                      | {"level": int.from_bytes(msg.status[0].level, "little")}]

        asked: dict[str, int] = {}  # question id -> replies received
        replies = {"answer": 0, "error": 0, "busy": 0, "partial": 0}
        unreadable = {"sent": 0, "replies": 0}  # malformed JSON: its id cannot be read, so the reply carries ""

        def on_reply(msg: String) -> None:
            data = json.loads(msg.data)
            with lock:
                if not data["final"]:  # what a decision question has decided so far; its final reply follows
                    replies["partial"] += 1
                    return
                if data["id"] == "":
                    unreadable["replies"] += 1
                else:
                    asked[data["id"]] = asked.get(data["id"], 0) + 1
                kind = "answer" if "answer" in data else "busy" if data.get("error", "").startswith("busy") else "error"
                replies[kind] += 1

        client.create_subscription(String, "/ipe/prediction", on_answer, LATCHED_QOS)
        client.create_subscription(String, "/ipe/answer", on_reply, ASK_QOS)
        ask_pub = client.create_publisher(String, "/ipe/ask", ASK_QOS)
        client.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
        json_pub = client.create_publisher(String, "/ipe/scene_json", 10)
        marker_pub = client.create_publisher(MarkerArray, "/ipe/scene", 10)
        deadline = time.monotonic() + 120
        while json_pub.get_subscription_count() == 0 or marker_pub.get_subscription_count() == 0:
            if time.monotonic() > deadline:
                raise SystemExit("the node did not subscribe within 120 s")
            time.sleep(0.1)

        tower = load_scenes(example_scene_path())[0]
        goods = [tower, capped_tower(3.0)] + [s for s in scene_catalogue(7, 12) if len(s.objects) <= 12]
        bads = _bad_inputs(capped_tower(3.0))
        counts = {"good": 0, "meshes": 0, "bad": 0, "flood": 0, "questions": 0, "hostile_questions": 0,
                  "question_floods": 0}
        question_serial = 0

        def ask(question: dict) -> None:
            nonlocal question_serial
            question_serial += 1
            key = f"q{question_serial}"
            malformed = question.get("question") == "fly"
            with lock:
                if malformed:
                    unreadable["sent"] += 1
                else:
                    asked.setdefault(key, 0)
            text = '{"id": "%s", "question": ' % key if malformed else json.dumps({"id": key, **question})
            ask_pub.publish(String(data=text))
        memory: list[tuple[float, float]] = []
        disk: list[tuple[float, float]] = []
        start = time.monotonic()
        end = start + 60 * args.minutes
        next_memory = start
        serial = 0

        def send_good(via_markers: bool) -> None:
            nonlocal serial
            serial += 1
            scene = dataclasses.replace(rng.choice(goods), name=f"soak_{serial}")
            with lock:
                sent_at[scene.name] = time.monotonic()
            if via_markers and all(b.shape.type in ("box", "sphere", "cylinder", "convex") for b in scene.objects):
                marker_pub.publish(scene_to_markers(scene, "world", time.time_ns()))
            else:
                json_pub.publish(String(data=scene_to_json(scene)))

        if args.only in ("questions", "question_floods"):  # questions are about the newest scene: one to ask about
            send_good(False)
            counts["good"] += 1
        while time.monotonic() < end:
            now = time.monotonic()
            if now >= next_memory:
                family_now = _family(node.pid)
                memory.append((now - start, _rss_mb(family_now), _rss_mb([node.pid])))
                disk.append((now - start, _disk_mb(cache)))
                next_memory += 10.0
            draw = rng.random()
            kind = args.only or next(k for k, upto in MIX if draw < upto)
            if kind == "good":
                send_good(rng.random() < 0.3)
                counts["good"] += 1
            elif kind == "meshes":  # a scene, or a question bringing it, holding one of the meshes
                file, minor = rng.choice(meshes)
                serial += 1
                scene = _mesh_scene(f"soak_{serial}", file, minor)
                if rng.random() < 0.5:
                    with lock:
                        sent_at[scene["name"]] = time.monotonic()
                    json_pub.publish(String(data=json.dumps(scene)))
                else:
                    ask({"question": "remove", "objects": ["block"], "samples": 4, "scene": scene})
                counts["meshes"] += 1
            elif kind == "bad":
                channel, msg = rng.choice(bads)
                (json_pub if channel == "json" else marker_pub).publish(msg)
                counts["bad"] += 1
            elif kind == "questions":
                ask(rng.choice(good_questions))
                counts["questions"] += 1
            elif kind == "hostile_questions":
                ask(rng.choice(hostile_questions))
                counts["hostile_questions"] += 1
            elif kind == "flood":
                for _ in range(20):
                    send_good(False)
                counts["flood"] += 1
            else:
                for _ in range(200):
                    ask(rng.choice(good_questions))
                counts["question_floods"] += 1
            time.sleep(rng.uniform(0.5, 1.5))
            if node.poll() is not None:
                break
        alive_at_end = node.poll() is None
        settled = time.monotonic() + args.settle_s  # let the last answers and diagnostics arrive,
        while time.monotonic() < settled + 120:  # and every question still waiting get its reply
            with lock:
                waiting = sum(1 for n in asked.values() if n == 0) + unreadable["sent"] - unreadable["replies"]
            if time.monotonic() >= settled and not waiting:
                break
            time.sleep(0.5)
    family = _family(node.pid)
    stop_started = time.monotonic()
    code = _stop(node)
    exit_s = time.monotonic() - stop_started
    time.sleep(1.0)
    left = [pid for pid in family if Path(f"/proc/{pid}").exists()
            and Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"]
    executor.shutdown()
    spinner.join(timeout=10.0)  # the spin thread must leave rcl before the context goes (else std::terminate)
    client.destroy_node()
    rclpy.try_shutdown(context=context)
    shutil.rmtree(work, ignore_errors=True)

    lat = np.array(latencies) if latencies else np.array([np.nan])
    rss = np.array([m for _, m, _ in memory])
    times_min = np.array([t for t, _, _ in memory]) / 60
    half = len(rss) // 2  # the trend after warm-up (imports, worker start, caches): flat or growing?
    slope = float(np.polyfit(times_min[half:], rss[half:], 1)[0]) if len(rss) - half >= 3 else float("nan")
    with lock:
        unanswered = sum(1 for n in asked.values() if n == 0)
        twice = sum(1 for n in asked.values() if n > 1)
    node_rss = np.array([m for _, _, m in memory])
    node_slope = float(np.polyfit(times_min[half:], node_rss[half:], 1)[0]) if len(rss) - half >= 3 else float("nan")
    # the node after warm-up (imports, worker start, caches, DDS discovery): its size at 10 min (or a
    # third of a shorter run), against which the end is compared (issue 50: within 10%)
    warm = int(np.searchsorted(times_min, min(10.0, times_min[-1] / 3))) if len(memory) else 0
    result = {
        "minutes": args.minutes, "only": args.only, "question_kinds": args.question_kinds, "date": time.strftime("%Y-%m-%d"), "sent": counts,
        "good_scenes_sent": counts["good"] + 20 * counts["flood"], "answers": answers,
        "answered_distinct_scenes": len(latencies), "node_alive_until_the_end": alive_at_end,
        "questions": {"asked": len(asked), "replies": replies, "without_reply": unanswered, "replied_twice": twice,
                      "unreadable": unreadable},
        "rss_slope_second_half_mb_per_10_min": 10 * slope,
        "node_rss_slope_second_half_mb_per_10_min": 10 * node_slope,
        "node_rss_after_warm_up_mb": float(node_rss[warm]) if len(memory) else None,
        "disk_mb": {"after_warm_up": disk[warm][1] if disk else None, "last": disk[-1][1] if disk else None,
                    "samples": [[round(t, 1), round(m, 2)] for t, m in disk]},
        "latency_s": {f"p{q}": float(np.percentile(lat, q)) for q in (50, 90, 99)} | {"max": float(lat.max())},
        "rss_mb": {"first": float(rss[0]), "last": float(rss[-1]), "max": float(rss.max()),
                   "node_first": float(node_rss[0]), "node_last": float(node_rss[-1]),
                   "samples": [[round(t, 1), round(m, 1), round(n, 1)] for t, m, n in memory]},
        "diagnostics_at_end": diagnostics[0] if diagnostics else None,
        "sigint_exit_s": exit_s, "exit_code": code, "processes_left": left,
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "soak.json").write_text(json.dumps(result, indent=1) + "\n")
    d = result["diagnostics_at_end"] or {}
    what = "mixed input" if args.only is None else f"{args.only} only"
    md = [f"# Soak: ipe_node for {args.minutes:g} min of {what} ({result['date']})", "",
          "`.venv/bin/python benchmarks/soak.py --minutes "
          f"{args.minutes:g}{'' if args.only is None else ' --only ' + args.only}"
          f"{'' if not args.question_kinds else ' --question-kinds ' + args.question_kinds}`; 2 workers, k = 8, budget 10 s, "
          "on this project's 2-core machine.", "",
          "| what | value |", "|---|---|",
          f"| sent | {counts['good']} good scenes, {counts['meshes']} scenes or questions holding one of "
          f"{args.meshes} + 1 meshes, {counts['bad']} bad inputs, {counts['flood']} floods of 20; "
          f"{counts['questions']} questions, {counts['hostile_questions']} hostile ones, "
          f"{counts['question_floods']} floods of 200 questions |",
          f"| question replies | {len(asked)} asked: {replies['answer']} answers, {replies['error']} errors, "
          f"{replies['busy']} busy ({replies['partial']} partial replies before finals); {unanswered} without reply, {twice} replied twice; {unreadable['sent']} "
          f"unreadable (malformed JSON, no id to echo): {unreadable['replies']} replies with id \"\" |",
          f"| answers | {answers['ok']} ({answers['budget']} cut by the budget), {answers['error']} error answers, "
          f"{answers['decomposing']} \"decomposing\" before an answer; meshes decomposed {d.get('meshes_decomposed', '-')}, "
          f"refused {d.get('meshes_refused', '-')} (diagnostics) |",
          f"| scenes rejected (diagnostics) | {d.get('scenes_rejected', '-')} |",
          f"| scenes dropped by keep-latest (diagnostics) | {d.get('scenes_dropped', '-')} |",
          f"| node up the whole time | {alive_at_end} |",
          f"| latency send -> answer, s | p50 {result['latency_s']['p50']:.2f}, p90 {result['latency_s']['p90']:.2f}, "
          f"p99 {result['latency_s']['p99']:.2f}, max {result['latency_s']['max']:.2f} |",
          f"| resident memory (node + workers), MB | first {rss[0]:.0f}, last {rss[-1]:.0f}, max {rss.max():.0f} |",
          f"| resident memory (node process alone), MB | first {node_rss[0]:.0f}, after warm-up (at "
          f"{times_min[warm]:.0f} min) {node_rss[warm]:.0f}, last {node_rss[-1]:.0f} "
          f"({100 * (node_rss[-1] / node_rss[warm] - 1):+.0f}%), max {node_rss.max():.0f} |",
          f"| disk (the mesh cache), MB | after warm-up {result['disk_mb']['after_warm_up']:.2f}, last "
          f"{result['disk_mb']['last']:.2f} |",
          f"| memory trend over the second half, MB per 10 min | node and workers {10 * slope:+.1f}, node alone "
          f"{10 * node_slope:+.1f} |",
          f"| SIGINT -> exit | {exit_s:.2f} s, exit code {code}, processes left: {len(left)} |", ""]
    (out / "soak.md").write_text("\n".join(md))
    print("\n".join(md))
    every_question_once = not unanswered and not twice and unreadable["sent"] == unreadable["replies"]
    return 0 if alive_at_end and not left and code == 0 and every_question_once else 1


if __name__ == "__main__":
    sys.exit(main())
