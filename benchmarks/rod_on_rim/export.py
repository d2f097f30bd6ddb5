"""The rod leaning on the handled mug's rim (tests/test_meshes.py's spoon: its end 3 mm from the far
wall, leaning over the near rim): pybullet's answers (the mug's final tilt under `default`, `fine`,
`paper`) and the start state after depenetration and set-down, for a third engine
(mujoco_tilt.py). Usage: export.py OUT.json [yaw_deg]"""
import json, math, sys, tempfile
from pathlib import Path
import numpy as np
from scipy.spatial.transform import Rotation
from ipe_ros.engine import ModelConfig, QuerySpec, load_scenes, predict, preset
from ipe_ros.engine import Request
from ipe_ros.engine.scene import household, shapes as S
from ipe_ros.engine.scene.shapes import rotation_matrix
from ipe_ros.engine.sampling.perturb import draw_sample_inputs
from ipe_ros.engine.sampling.rollout import separated_world
from ipe_ros.engine.simulation.world import read_state

R_OUT, R_IN, HEIGHT, BOTTOM = 0.04, 0.035, 0.1, 0.006

def scene(folder, kg, yaw_deg):
    v, f = household.mug()
    household.write_obj(Path(folder) / "mug.obj", v, f)
    far = -R_IN + 0.003
    angle = math.atan2(HEIGHT - BOTTOM, R_IN - far)
    along, across = np.array([math.cos(angle), 0, math.sin(angle)]), np.array([-math.sin(angle), 0, math.cos(angle)])
    length, width, thickness = 0.4, 0.012, 0.004
    centre = np.array([far, 0, BOTTOM]) + length / 2 * along + thickness / 2 * across + [0, 0, 0.002]
    turn = Rotation.from_euler("z", math.radians(yaw_deg))
    lean = turn * Rotation.from_euler("y", -angle)
    data = {"format": "ipe_ros.scene/2", "name": "rim", "gravity_m_s2": [0, 0, -9.81], "set_down_m": 0.01,
            "support": {"type": "floor", "height_m": 0.0, "friction": 0.6, "restitution": 0.0},
            "objects": [{"name": "mug", "shape": {"type": "mesh", "uri": "mug.obj"}, "position_m": [0, 0, 0],
                         "orientation_xyzw": turn.as_quat().tolist(), "friction": 0.6, "restitution": 0.0,
                         "density_kg_m3": 2000},
                        {"name": "spoon", "shape": {"type": "box", "extents_m": [length, width, thickness]},
                         "position_m": turn.apply(centre).tolist(), "orientation_xyzw": lean.as_quat().tolist(),
                         "friction": 0.6, "restitution": 0.0, "mass_kg": kg}]}
    (Path(folder) / "s.json").write_text(json.dumps(data))
    return load_scenes(Path(folder) / "s.json")[0]

def tilt(scene, name):
    a = predict(scene,
                Request(model=ModelConfig(sigma_m=0.0, samples=1, object_noise=False), settings=preset(name),
                        query=QuerySpec(queries=frozenset({"final_pose", "tipped"})), check=None, budget_s=None))
    up = rotation_matrix(a.outcomes[0].rollouts[0].final_orientations_xyzw[0])[2, 2]
    return round(float(np.degrees(np.arccos(min(1.0, abs(up))))), 1)

def main():
    out, yaw = sys.argv[1], float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for kg in (0.2, 0.3, 0.36, 0.42, 0.48, 0.6):
            sc = scene(folder, kg, yaw)
            answers = {n: tilt(sc, n) for n in ("default", "fine", "paper")}
            inputs = draw_sample_inputs(sc, ModelConfig(sigma_m=0.0, object_noise=False), np.random.default_rng(0))
            world = separated_world(sc, preset("paper"), inputs)
            com, orn, _ = read_state(world)
            bodies = []
            for i, b in enumerate(sc.dynamic_objects):
                com_local = S.centre_of_mass_m(b.shape)
                parts = []
                if isinstance(b.shape, S.Compound):
                    for part in b.shape.parts:
                        R = rotation_matrix(part.orientation_xyzw)
                        verts = np.asarray(part.shape.vertices_m) @ R.T + np.asarray(part.position_m) - com_local
                        parts.append({"hull": verts.tolist()})
                    inertia = (np.asarray(b.shape.inertia_diagonal_per_kg_m2) * b.resolved_mass_kg).tolist()
                else:
                    e = np.asarray(b.shape.extents_m)
                    parts.append({"box_half": (e / 2).tolist()})
                    m = b.resolved_mass_kg
                    inertia = [m / 12 * (e[1]**2 + e[2]**2), m / 12 * (e[0]**2 + e[2]**2), m / 12 * (e[0]**2 + e[1]**2)]
                bodies.append({"name": b.name, "mass": b.resolved_mass_kg, "inertia": inertia, "com": com[i].tolist(),
                               "quat_xyzw": orn[i].tolist(), "friction": b.friction, "parts": parts})
            rows.append({"spoon_kg": kg, "pybullet_tilt_deg": answers, "bodies": bodies})
            print(kg, answers, flush=True)
    Path(out).write_text(json.dumps(rows))

if __name__ == "__main__":
    main()
