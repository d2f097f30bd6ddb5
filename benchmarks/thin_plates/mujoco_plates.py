"""A third engine's answer for the zoo's thin plates: which plates MuJoCo lets fall, per sample.

Runs in a venv of its own (MuJoCo is not one of the package's dependencies):

    python3 -m venv /tmp/mj && /tmp/mj/bin/pip install mujoco==4.0.0 numpy
    .venv/bin/python benchmarks/thin_plates/export.py /tmp/plates.json      # pybullet's answers, start states
    /tmp/mj/bin/python benchmarks/thin_plates/mujoco_plates.py /tmp/plates.json

Each sample starts from pybullet's state after depenetration. Friction between two bodies is the
product of theirs, as Bullet combines it (each pair is given explicitly; MuJoCo would take the
larger), no restitution; 2 s under several contact settings. A plate has fallen when its centre
dropped by more than the fall query's fraction of its thickness, as in the package. The table gives
P(fall) per plate, then per sample whether the plate where pybullet's physics part most fell, and each
pybullet physics' per-sample agreement with MuJoCo's hard friction (noslip: no creep under static
friction).
"""

import json
import sys

import mujoco
import numpy as np

VARIANTS = [  # name, time step (s), solref, solimp, cone, noslip iterations
    ("0.5 ms, soft 0.02", 0.0005, "0.02 1", "0.9 0.95 0.001", "pyramidal", 0),
    ("0.5 ms, elliptic", 0.0005, "0.02 1", "0.9 0.95 0.001", "elliptic", 0),
    ("0.25 ms, stiff 0.004, elliptic", 0.00025, "0.004 1", "0.9 0.95 0.001", "elliptic", 0),
    ("0.25 ms, stiff, noslip", 0.00025, "0.004 1", "0.9 0.95 0.001", "elliptic", 10),
]
HARD_FRICTION = VARIANTS[-1][0]


def model_xml(sample: dict, floor_friction: float, timestep: float, solref: str, solimp: str, cone: str,
              noslip: int) -> str:
    bodies, pairs = [], []
    frictions = {b["name"]: b["friction"] for b in sample["bodies"]}
    names = list(frictions)
    for b in sample["bodies"]:
        h, (x, y, z, w) = b["half"], b["quat_xyzw"]
        bodies.append(f'<body name="{b["name"]}" pos="{" ".join(map(str, b["com"]))}" quat="{w} {x} {y} {z}">'
                      f'<freejoint/><inertial pos="0 0 0" mass="{b["mass"]}" '
                      f'diaginertia="{" ".join(map(str, b["inertia"]))}"/>'
                      f'<geom name="g_{b["name"]}" type="box" size="{h[0]} {h[1]} {h[2]}" contype="0" '
                      f'conaffinity="0"/></body>')

    def pair(a: str, b: str, mu: float) -> str:
        return (f'<pair geom1="{a}" geom2="{b}" friction="{mu} {mu} 0.001 0.0001 0.0001" solref="{solref}" '
                f'solimp="{solimp}" condim="3"/>')

    for i, a in enumerate(names):
        pairs.append(pair("floor", f"g_{a}", frictions[a] * floor_friction))
        pairs += [pair(f"g_{a}", f"g_{b}", frictions[a] * frictions[b]) for b in names[i + 1:]]
    return (f'<mujoco><option timestep="{timestep}" cone="{cone}" noslip_iterations="{noslip}" iterations="200" '
            f'tolerance="1e-10"/><compiler inertiafromgeom="false"/><worldbody>'
            f'<geom name="floor" type="plane" size="5 5 0.1" contype="0" conaffinity="0"/>{"".join(bodies)}'
            f'</worldbody><contact>{"".join(pairs)}</contact></mujoco>')


def fallen(sample: dict, floor_friction: float, threshold_fraction: float, variant: tuple) -> np.ndarray:
    _, timestep, *contact = variant
    model = mujoco.MjModel.from_xml_string(model_xml(sample, floor_friction, timestep, *contact))
    data = mujoco.MjData(model)
    start = np.array([b["com"][2] for b in sample["bodies"]])
    for _ in range(int(round(2.0 / timestep))):
        mujoco.mj_step(model, data)
    end = np.array([data.qpos[7 * i + 2] for i in range(len(start))])
    thickness = np.array([2 * min(b["half"]) for b in sample["bodies"]])
    return start - end > threshold_fraction * thickness


def main() -> None:
    for row in json.load(open(sys.argv[1])):
        answers = {f"MuJoCo {v[0]}": np.array([fallen(s, row["floor_friction"], row["fall_threshold_fraction"], v)
                                               for s in row["samples"]]) for v in VARIANTS}
        answers.update({f"pybullet {n}": np.array(f) for n, f in row["pybullet_fallen"].items()})
        means = {n: a.mean(axis=0) for n, a in answers.items()}
        # the plate where pybullet's physics part most
        parted = int(np.argmax(np.ptp(np.array([m for n, m in means.items() if n.startswith("pybullet")]), axis=0)))
        hard = answers[f"MuJoCo {HARD_FRICTION}"][:, parted]
        print(f"\n### {row['scene']} ({len(row['samples'])} samples)\n")
        print("| physics | " + " | ".join(row["names"]) + f" | {row['names'][parted]}, per sample | "
              "agrees with hard friction |")
        print("|---|" + "---|" * (len(row["names"]) + 2))
        for name, a in answers.items():
            print(f"| {name} | " + " | ".join(f"{p:.2f}" for p in means[name]) + " | "
                  + "".join(str(int(x)) for x in a[:, parted]) + f" | {np.mean(a[:, parted] == hard):.0%} |",
                  flush=True)


if __name__ == "__main__":
    main()
