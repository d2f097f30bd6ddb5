"""Observed motion made by MuJoCo: each case of observations.py rolled out in MuJoCo (as
mujoco_run.py builds scenes: Bullet's friction product, elliptic cones, hard contacts, restitution as
a damping ratio) and read at the observation's frame times with the tracker's noise.

    /tmp/mj/bin/python benchmarks/witness/mujoco_observe.py CASES.json OBSERVED_DIR

Writes one ``ipe_ros.observation/1`` file per case (``<family>_<seed>.json``, with ``"truth"``,
``"nominal"``, ``"heavier"`` and ``"scored"`` beside it for benchmarks/inference.py --observed). A
friction or a restitution means what the contact model makes of it, and MuJoCo's soft contacts make
something else of the same number than Bullet's (and the world than either): the truth scored is
what closed-form mechanics reads off MuJoCo's own motion (a slide's stop, a bounce's rebound), the
number MuJoCo was given is kept as ``nominal``. Masses are scored as given.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import mujoco
import numpy as np

from mujoco_run import TIME_STEP_S, model_xml


def frames(row: dict, rng: np.random.Generator) -> tuple[list[dict], dict]:
    """The observation's frames as MuJoCo makes them, and what closed-form mechanics reads off the
    same motion (noiseless) for the properties whose meaning is the contact model's."""
    scene, observation = row["scene"], row["observation"]
    xml, order = model_xml(scene, row["start_m"], row["start_xyzw"])
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    for b in scene["dynamic"]:
        address = model.jnt_dofadr[model.body(b["name"]).jntadr[0]]
        data.qvel[address:address + 3] = b["linear_velocity_m_s"]
    sd = observation["position_sd_m"]
    first = model.jnt_dofadr[model.body(order[0]).jntadr[0]]
    out, vertical = [], []
    for frame in observation["frames"]:
        while data.time < frame["t_s"] - TIME_STEP_S / 2:
            mujoco.mj_step(model, data)
            vertical.append(float(data.qvel[first + 2]))  # the first object's vertical speed (a free joint's, world)
        objects = {}
        for name in order:  # a box's and a ball's frame is its centre of mass
            seen = data.body(name).xpos + sd * rng.standard_normal(3)
            objects[name] = {"position_m": [round(float(v), 6) for v in seen]}
        out.append({"t_s": frame["t_s"], "objects": objects})
    return out, _effective(row, data, order, np.array(vertical))


def _effective(row: dict, data, order: list[str], vertical_m_s: np.ndarray) -> dict:
    """A slide's friction from where it stopped, v^2 / (2 g d); a bounce's restitution from its first
    rebound, v_up / v_down: what the motion says, in any engine (a mass needs no reading: it is one)."""
    family, scene = row["family"], row["scene"]
    g = float(np.linalg.norm(scene["gravity_m_s2"]))
    if family == "slide":
        travel = np.linalg.norm(data.body(order[0]).xpos[:2] - np.asarray(row["start_m"][0][:2]))
        speed = np.linalg.norm(scene["dynamic"][0]["linear_velocity_m_s"])
        return {"box.friction": float(speed ** 2 / (2 * g * travel))}
    if family == "bounce":
        down = int(np.argmin(vertical_m_s))  # the fastest fall: just before the first impact
        return {"ball.restitution": float(np.max(vertical_m_s[down:]) / -vertical_m_s[down])}
    return {}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases")
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for row in json.load(open(args.cases))["rows"]:
        made, effective = frames(row, np.random.default_rng(row["seed"]))
        observation = {**row["observation"], "frames": made}
        path = args.out / f"{row['family']}_{row['seed']}.json"
        # scored against what the motion says where the contact model gives a property its meaning
        path.write_text(json.dumps({**observation, "truth": {**row["truth"], **effective}, "nominal": row["truth"],
                                    "heavier": row["heavier"], "scored": row["scored"]}))
        print(path, flush=True)


if __name__ == "__main__":
    main()
