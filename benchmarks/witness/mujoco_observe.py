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
    out, heights = [], []
    for frame in observation["frames"]:
        while data.time < frame["t_s"] - TIME_STEP_S / 2:
            mujoco.mj_step(model, data)
            heights.append((float(data.time), float(data.body(order[0]).xpos[2])))  # the first object's
        objects = {}
        for name in order:  # a box's and a ball's frame is its centre of mass
            seen = data.body(name).xpos + sd * rng.standard_normal(3)
            objects[name] = {"position_m": [round(float(v), 6) for v in seen]}
        out.append({"t_s": frame["t_s"], "objects": objects})
    return out, _effective(row, data, order, np.array(heights))


def _effective(row: dict, data, order: list[str], heights: np.ndarray) -> dict:
    """A slide's friction from where it stopped, v^2 / (2 g d); a bounce's restitution as the one
    constant e whose closed-form bounces (instant, e of the landing speed) best fit the ball's heights
    over the window (MuJoCo's soft contacts give back more of a fast landing than of a slow one: 0.73
    of 3 m/s, 0.57 of 1-2 m/s for e = 0.58): what the motion says, in any engine (a mass needs no
    reading: it is one)."""
    family, scene = row["family"], row["scene"]
    g = float(np.linalg.norm(scene["gravity_m_s2"]))
    if family == "slide":
        travel = np.linalg.norm(data.body(order[0]).xpos[:2] - np.asarray(row["start_m"][0][:2]))
        speed = np.linalg.norm(scene["dynamic"][0]["linear_velocity_m_s"])
        return {"box.friction": float(speed ** 2 / (2 * g * travel))}
    if family == "bounce":
        radius = scene["dynamic"][0]["parts"][0]["radius_m"]
        start = row["start_m"][0][2]
        grid = np.arange(0.0, 1.0, 0.001)
        misfit = [np.mean((_bouncing(heights[:, 0], start, radius, g, e) - heights[:, 1]) ** 2) for e in grid]
        return {"ball.restitution": float(grid[int(np.argmin(misfit))])}
    return {}


def _bouncing(times_s: np.ndarray, start_m: float, radius_m: float, g: float, e: float) -> np.ndarray:
    """A ball's centre dropped from rest at ``start_m``: instant bounces at ``radius_m``, each e of
    the landing speed (closed form)."""
    out = np.empty_like(times_s)
    t0, z0, v0, resting = 0.0, start_m, 0.0, False
    for i, t in enumerate(times_s):
        while not resting:
            # the next landing: z0 + v0 s - g s^2 / 2 = radius
            s_land = (v0 + np.sqrt(v0 * v0 + 2 * g * max(z0 - radius_m, 0.0))) / g
            if t < t0 + s_land:
                break
            t0, z0, v0 = t0 + s_land, radius_m, e * (g * s_land - v0)
            resting = v0 < 1e-3
        s = t - t0
        out[i] = radius_m if resting else max(radius_m, z0 + v0 * s - g * s * s / 2)
    return out


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
