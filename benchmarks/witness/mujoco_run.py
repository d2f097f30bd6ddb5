"""MuJoCo's side of the cross-engine witness: the exported starts run in MuJoCo, held against pybullet.

    /tmp/mj/bin/python benchmarks/witness/mujoco_run.py OUT.json [--md REPORT.md] [--json RESULT.json]
                                                        [--timeconst-s 0.002] [--step-s 0.00025]

(see export.py for the venv and the export). MuJoCo runs every sample from pybullet's start: each
body at its centre of mass with pybullet's mass and principal inertia, its shape as geoms (a hull as
a mesh, which MuJoCo takes as its convex hull), the scene's initial velocities.

Surfaces as Bullet combines them: every pair of geoms that can touch is an explicit contact pair
with the product of the two frictions (MuJoCo alone would take the larger) and an elliptic cone (a
true Coulomb cone), hard contacts (``TIMECONST_S``, impratio 10, noslip iterations: MuJoCo's contacts
are soft, and its friction creeps without them). Restitution: MuJoCo's contacts are damped springs,
whose damping ratio zeta gives back e = exp(-zeta pi / sqrt(1 - zeta^2)) of the approach speed; each
pair's zeta is chosen for the product of the two restitutions (e = 0: critically damped).

Reported: for the mechanics cases, each engine's answer beside the closed form; for the zoo's
families, per family, how often the engines agree on "did this object fall?" (per object and
sample), mean |dP(object falls)| over the family's objects, and the median distance between the two
engines' final positions of the objects neither has fall, as a share of the object's size.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import mujoco
import numpy as np

TIME_STEP_S = 0.00025
TIMECONST_S = 0.002
NOSLIP_ITERATIONS = 10


def _wxyz(q_xyzw):
    x, y, z, w = q_xyzw
    return f"{w} {x} {y} {z}"


def _rotation(q_xyzw) -> np.ndarray:
    x, y, z, w = q_xyzw
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def damping_ratio(restitution: float) -> float:
    """The damping ratio of a contact spring that gives back ``restitution`` of the approach speed."""
    if restitution <= 0:
        return 1.0
    log_e = math.log(min(restitution, 0.999))
    return -log_e / math.sqrt(math.pi ** 2 + log_e ** 2)


def _geom(part: dict, name: str, assets: list) -> str:
    placed = f'name="{name}" pos="{" ".join(map(str, part["pos"]))}" quat="{_wxyz(part["quat_xyzw"])}" ' \
             f'contype="0" conaffinity="0"'
    kind = part["type"]
    if kind == "box":
        return f'<geom type="box" size="{" ".join(map(str, part["half_m"]))}" {placed}/>'
    if kind == "sphere":
        return f'<geom type="sphere" size="{part["radius_m"]}" {placed}/>'
    if kind in ("cylinder", "capsule"):
        return f'<geom type="{kind}" size="{part["radius_m"]} {part["half_length_m"]}" {placed}/>'
    assets.append(f'<mesh name="{name}_mesh" vertex="{" ".join(f"{v:.9g}" for p in part["points_m"] for v in p)}"/>')
    return f'<geom type="mesh" mesh="{name}_mesh" {placed}/>'


def model_xml(scene: dict, positions_m, orientations_xyzw) -> tuple[str, list[str]]:
    assets, bodies, geoms_of = [], [], {}
    floor = scene["floor"]
    surfaces = {"floor": (floor["friction"], floor["restitution"])}
    static_geoms = [f'<geom name="floor" type="plane" size="0 0 1" pos="0 0 {floor["height_m"]}" contype="0" '
                    f'conaffinity="0"/>']
    geoms_of["floor"] = ["floor"]
    for s in scene["static"]:
        names = [f'{s["name"]}_{j}' for j in range(len(s["parts"]))]
        inner = "".join(_geom(part, n, assets) for part, n in zip(s["parts"], names))
        static_geoms.append(f'<body name="{s["name"]}" pos="{" ".join(map(str, s["position_m"]))}" '
                            f'quat="{_wxyz(s["quat_xyzw"])}">{inner}</body>')
        geoms_of[s["name"]] = names
        surfaces[s["name"]] = (s["friction"], s["restitution"])
    order = []
    for b, position, orientation in zip(scene["dynamic"], positions_m, orientations_xyzw):
        names = [f'{b["name"]}_{j}' for j in range(len(b["parts"]))]
        inner = "".join(_geom(part, n, assets) for part, n in zip(b["parts"], names))
        inertia = " ".join(f"{max(v, 1e-12):.9g}" for v in b["inertia_kg_m2"])
        bodies.append(f'<body name="{b["name"]}" pos="{" ".join(map(str, position))}" quat="{_wxyz(orientation)}">'
                      f'<freejoint/><inertial pos="0 0 0" mass="{b["mass_kg"]}" diaginertia="{inertia}"/>{inner}</body>')
        geoms_of[b["name"]] = names
        surfaces[b["name"]] = (b["friction"], b["restitution"])
        order.append(b["name"])
    pairs = []
    names = list(geoms_of)
    dynamic = set(order)
    for i, first in enumerate(names):
        for second in names[i + 1:]:
            if first not in dynamic and second not in dynamic:
                continue
            friction = surfaces[first][0] * surfaces[second][0]
            zeta = damping_ratio(surfaces[first][1] * surfaces[second][1])
            for g1 in geoms_of[first]:
                for g2 in geoms_of[second]:
                    pairs.append(f'<pair geom1="{g1}" geom2="{g2}" condim="3" friction="{friction} {friction} 0 0 0" '
                                 f'solref="{TIMECONST_S} {zeta:.6f}" solimp="0.95 0.99 0.001"/>')
    gravity = " ".join(map(str, scene["gravity_m_s2"]))
    xml = (f'<mujoco><option timestep="{TIME_STEP_S}" gravity="{gravity}" cone="elliptic" impratio="10" '
           f'noslip_iterations="{NOSLIP_ITERATIONS}" iterations="100" tolerance="1e-10"/>'
           f'<compiler inertiafromgeom="false"/><asset>{"".join(assets)}</asset>'
           f'<worldbody>{"".join(static_geoms)}{"".join(bodies)}</worldbody>'
           f'<contact>{"".join(pairs)}</contact></mujoco>')
    return xml, order


def run_sample(scene: dict, sample: dict) -> np.ndarray:
    """MuJoCo's final centres of mass from the sample's start, at the scene's horizon."""
    xml, order = model_xml(scene, sample["initial_m"], sample["initial_xyzw"])
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    for i, b in enumerate(scene["dynamic"]):
        address = model.jnt_dofadr[model.body(b["name"]).jntadr[0]]
        rotation = _rotation(sample["initial_xyzw"][i])
        data.qvel[address:address + 3] = b["linear_velocity_m_s"]
        data.qvel[address + 3:address + 6] = rotation.T @ np.asarray(b["angular_velocity_rad_s"], float)  # body frame
    mujoco.mj_step(model, data, nstep=int(round(scene["horizon_s"] / TIME_STEP_S)))
    return np.array([data.body(name).xpos.copy() for name in order])


def _mechanics_line(row: dict, mujoco_final: np.ndarray) -> str:
    closed = row["closed_form"]
    pybullet_final = np.asarray(row["samples"][0]["pybullet_final_m"])
    start = np.asarray(row["samples"][0]["initial_m"])

    def describe(final):
        if "height_m" in closed:
            return f"{final[0, 2]:.4f} m high"
        heading = math.radians(closed["heading_deg"])
        along = np.array([math.cos(heading), math.sin(heading), 0.0])
        if "along_m" in closed:
            return " / ".join(f"{(final[i] - start[0]) @ along:.4f}" for i in range(len(final))) + " m along"
        travel = final[0] - start[0]
        off = math.degrees(math.remainder(math.atan2(travel[1], travel[0]) - heading, 2 * math.pi))
        return f"{math.hypot(travel[0], travel[1]):.4f} m at {off:+.1f} deg"

    if "height_m" in closed:
        expected = f"{closed['height_m']:.4f} m high"
    elif "along_m" in closed:
        expected = " / ".join(f"{v:.4f}" for v in closed["along_m"]) + " m along"
    else:
        expected = f"{closed['travel_m']:.4f} m at +0.0 deg"
    return f"| {row['label']} | {expected} | {describe(pybullet_final)} | {describe(mujoco_final)} |"


def main() -> None:
    global TIMECONST_S, TIME_STEP_S
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("exported")
    parser.add_argument("--md", default=None)
    parser.add_argument("--json", default=None)
    parser.add_argument("--timeconst-s", type=float, default=TIMECONST_S,
                        help="the contacts' time constant (smaller: harder; whether an answer depends on it)")
    parser.add_argument("--step-s", type=float, default=TIME_STEP_S, help="MuJoCo's step (at most a quarter of the time constant)")
    args = parser.parse_args()
    TIMECONST_S, TIME_STEP_S = args.timeconst_s, args.step_s
    data = json.load(open(args.exported))
    lines = ["## Mechanics: closed form, pybullet (`%s`), MuJoCo" % data["args"]["preset"], "",
             "| case | closed form | pybullet | MuJoCo |", "|---|---|---|---|"]
    families: dict[str, dict] = {}
    rows_fallen: dict[str, dict] = {}
    for row in data["rows"]:
        scene = row["scene"]
        finals = [run_sample(scene, sample) for sample in row["samples"]]
        if row["kind"] == "mechanics":
            lines.append(_mechanics_line(row, finals[0]))
            print(lines[-1], flush=True)
            continue
        tally = families.setdefault(row["kind"], {"agree": 0, "count": 0, "dp": [], "apart": [], "scenes": 0})
        tally["scenes"] += 1
        sizes = np.array([b["smallest_extent_m"] for b in scene["dynamic"]])
        fell_pb, fell_mj = [], []
        for sample, final in zip(row["samples"], finals):
            start = np.asarray(sample["initial_m"])
            mj = start[:, 2] - final[:, 2] > row["fall_threshold_fraction"] * sizes
            pb = np.asarray(sample["pybullet_fallen"], bool)
            fell_pb.append(pb)
            fell_mj.append(mj)
            tally["agree"] += int(np.sum(pb == mj))
            tally["count"] += len(pb)
            both_stand = ~pb & ~mj
            if both_stand.any():
                apart = np.linalg.norm(final - np.asarray(sample["pybullet_final_m"]), axis=1) / sizes
                tally["apart"].extend(apart[both_stand].tolist())
        tally["dp"].extend(np.abs(np.mean(fell_pb, axis=0) - np.mean(fell_mj, axis=0)).tolist())
        rows_fallen[row["label"]] = {"pybullet": np.mean(fell_pb, axis=0).tolist(),
                                     "mujoco": np.mean(fell_mj, axis=0).tolist()}
        print(f"{row['label']}: P(fall) pybullet {np.round(np.mean(fell_pb, axis=0), 2).tolist()} "
              f"MuJoCo {np.round(np.mean(fell_mj, axis=0), 2).tolist()}", flush=True)
    if families:
        lines += ["", "## The zoo's families: the same noisy starts in both engines", "",
                  "| family | scenes | objects x samples | agree on falling | mean \\|dP(falls)\\| | "
                  "median end apart (standing, x size) |", "|---|---|---|---|---|---|"]
        for family, t in families.items():
            apart = f"{np.median(t['apart']):.3f}" if t["apart"] else "-"
            lines.append(f"| {family} | {t['scenes']} | {t['count']} | {t['agree'] / max(1, t['count']):.1%} | "
                         f"{np.mean(t['dp']):.3f} | {apart} |")
    report = "\n".join(lines) + "\n"
    print(report)
    if args.md:
        open(args.md, "w").write(report)
    if args.json:
        json.dump({"families": {k: {"agree": v["agree"], "count": v["count"], "mean_abs_dP": float(np.mean(v["dp"])),
                                    "median_apart": float(np.median(v["apart"])) if v["apart"] else None}
                                for k, v in families.items()},
                   "p_fall": rows_fallen, "preset": data["rows"][0]["preset"] if data["rows"] else None,
                   "timeconst_s": TIMECONST_S, "step_s": TIME_STEP_S}, open(args.json, "w"), indent=1)


if __name__ == "__main__":
    sys.exit(main())
