"""Observed motion made by MuJoCo: each case of observations.py rolled out in MuJoCo (as
mujoco_run.py builds scenes: Bullet's friction product, elliptic cones, hard contacts, restitution as
a damping ratio) and read at the observation's frame times with the tracker's noise.

    /tmp/mj/bin/python benchmarks/witness/mujoco_observe.py CASES.json OBSERVED_DIR

Writes one ``ipe_ros.observation/1`` file per case (``<family>_<seed>.json``, with ``"truth"``,
``"heavier"`` and ``"scored"`` beside it for benchmarks/inference.py --observed).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import mujoco
import numpy as np

from mujoco_run import TIME_STEP_S, model_xml


def frames(row: dict, rng: np.random.Generator) -> list[dict]:
    scene, observation = row["scene"], row["observation"]
    xml, order = model_xml(scene, row["start_m"], row["start_xyzw"])
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    for b in scene["dynamic"]:
        address = model.jnt_dofadr[model.body(b["name"]).jntadr[0]]
        data.qvel[address:address + 3] = b["linear_velocity_m_s"]
    sd = observation["position_sd_m"]
    out = []
    for frame in observation["frames"]:
        mujoco.mj_step(model, data, nstep=max(0, int(round(frame["t_s"] / TIME_STEP_S)) - int(round(data.time / TIME_STEP_S))))
        objects = {}
        for name in order:  # a box's and a ball's frame is its centre of mass
            seen = data.body(name).xpos + sd * rng.standard_normal(3)
            objects[name] = {"position_m": [round(float(v), 6) for v in seen]}
        out.append({"t_s": frame["t_s"], "objects": objects})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases")
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for row in json.load(open(args.cases))["rows"]:
        observation = {**row["observation"], "frames": frames(row, np.random.default_rng(row["seed"]))}
        path = args.out / f"{row['family']}_{row['seed']}.json"
        path.write_text(json.dumps({**observation, "truth": row["truth"], "heavier": row["heavier"],
                                    "scored": row["scored"]}))
        print(path, flush=True)


if __name__ == "__main__":
    main()
