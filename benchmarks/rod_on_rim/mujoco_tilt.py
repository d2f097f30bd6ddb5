"""A third engine's answer for the rod leaning on the handled mug's rim: MuJoCo's final tilt of the mug.

Runs in a venv of its own (MuJoCo is not one of the package's dependencies):

    python3 -m venv /tmp/mj && /tmp/mj/bin/pip install mujoco==4.0.0 numpy
    .venv/bin/python benchmarks/rod_on_rim/export.py /tmp/rim.json   # pybullet's answers, the start state
    /tmp/mj/bin/python benchmarks/rod_on_rim/mujoco_tilt.py /tmp/rim.json           # every exported rod
    /tmp/mj/bin/python benchmarks/rod_on_rim/mujoco_tilt.py /tmp/rim.json --sweep   # the first, over masses

The start state is pybullet's after depenetration and set-down, so both engines start alike: each
body at its centre of mass with its orientation, mass and diagonal inertia, the mug as its convex
parts (MuJoCo takes each mesh geom's hull), friction 0.6, no restitution. Each row runs 2 s under
several contact settings (MuJoCo's contacts are soft: their time constant and impedance decide how
far bodies sink).
"""

import copy
import json
import sys

import mujoco
import numpy as np

VARIANTS = [  # name, time step (s), solref, solimp, cone, noslip iterations
    ("0.5 ms, soft 0.02", 0.0005, "0.02 1", "0.9 0.95 0.001", "pyramidal", 0),
    ("0.5 ms, elliptic", 0.0005, "0.02 1", "0.9 0.95 0.001", "elliptic", 0),
    ("0.25 ms, stiff 0.004, elliptic", 0.00025, "0.004 1", "0.9 0.95 0.001", "elliptic", 0),
    ("0.25 ms, stiff, noslip", 0.00025, "0.004 1", "0.9 0.95 0.001", "elliptic", 10),
    ("0.1 ms, stiffer 0.001, solimp 0.99", 0.0001, "0.001 1", "0.99 0.999 0.0005", "elliptic", 0),
]


def model_xml(row: dict, timestep: float, solref: str, solimp: str, cone: str, noslip: int) -> str:
    assets, bodies = [], []
    contact = f'friction="{{f}} 0 0" solref="{solref}" solimp="{solimp}" condim="3"'
    for b in row["bodies"]:
        geoms = []
        for j, part in enumerate(b["parts"]):
            if "hull" in part:
                name = f"{b['name']}_{j}"
                assets.append(f'<mesh name="{name}" vertex="{" ".join(f"{v:.9g}" for p in part["hull"] for v in p)}"/>')
                geoms.append(f'<geom type="mesh" mesh="{name}" {contact.format(f=b["friction"])}/>')
            else:
                h = part["box_half"]
                geoms.append(f'<geom type="box" size="{h[0]} {h[1]} {h[2]}" {contact.format(f=b["friction"])}/>')
        x, y, z, w = b["quat_xyzw"]
        inertia = " ".join(map(str, b["inertia"]))
        bodies.append(f'<body name="{b["name"]}" pos="{" ".join(map(str, b["com"]))}" quat="{w} {x} {y} {z}">'
                      f'<freejoint/><inertial pos="0 0 0" mass="{b["mass"]}" diaginertia="{inertia}"/>'
                      f'{"".join(geoms)}</body>')
    return (f'<mujoco><option timestep="{timestep}" cone="{cone}" noslip_iterations="{noslip}" iterations="200" '
            f'tolerance="1e-10"/><compiler inertiafromgeom="false"/><asset>{"".join(assets)}</asset><worldbody>'
            f'<geom type="plane" size="5 5 0.1" {contact.format(f=0.6)}/>{"".join(bodies)}</worldbody></mujoco>')


def mug_tilt_deg(row: dict, variant: tuple) -> float:
    """The mug's (the first body's) tilt after 2 s, degrees."""
    _, timestep, *rest = variant
    model = mujoco.MjModel.from_xml_string(model_xml(row, timestep, *rest))
    data = mujoco.MjData(model)
    for _ in range(int(round(2.0 / timestep))):
        mujoco.mj_step(model, data)
    matrix = np.zeros(9)
    mujoco.mju_quat2Mat(matrix, data.qpos[3:7])
    return float(np.degrees(np.arccos(min(1.0, abs(matrix[8])))))


def with_rod_mass(row: dict, kg: float) -> dict:
    out = copy.deepcopy(row)
    rod = out["bodies"][1]
    rod["inertia"] = [v * kg / rod["mass"] for v in rod["inertia"]]
    rod["mass"] = kg
    return out


def main() -> None:
    rows = json.load(open(sys.argv[1]))
    if "--sweep" in sys.argv:
        for variant in VARIANTS[2:]:
            cells = [f"{kg}: {mug_tilt_deg(with_rod_mass(rows[0], kg), variant):.0f}"
                     for kg in (0.1, 0.15, 0.2, 0.25, 0.3, 0.36, 0.42, 0.48, 0.6)]
            print(f"| {variant[0]} | " + " | ".join(cells) + " |", flush=True)
        return
    print("| rod | pybullet default / fine / paper | " + " | ".join(v[0] for v in VARIANTS) + " |")
    for row in rows:
        p = row["pybullet_tilt_deg"]
        cells = [f"{mug_tilt_deg(row, v):.1f}" for v in VARIANTS]
        print(f"| {row['spoon_kg']} kg | {p['default']} / {p['fine']} / {p['paper']} | " + " | ".join(cells) + " |",
              flush=True)


if __name__ == "__main__":
    main()
