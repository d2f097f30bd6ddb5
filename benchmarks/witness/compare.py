"""Several runs of the same exported starts side by side: pybullet's presets and solver settings
(export.py) and MuJoCo at several contact stiffnesses (mujoco_run.py --json), per row.

    .venv/bin/python benchmarks/witness/compare.py --pybullet paper=A.json --pybullet paper-200it=B.json \\
        --mujoco mujoco-2ms=C.json [--md OUT.md]

For each row (a scene: a zoo scene, or a removal variant of the robot questions' tower), every run's
P(object falls) per object, and for every pair of runs the mean |dP| over the row's objects, then
over all rows. Runs must come from the same starts (the same seed and noise) to be compared sample
by sample; MuJoCo's results carry the pybullet export they ran from.
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def pybullet_p_fall(path: str) -> dict[str, np.ndarray]:
    data = json.load(open(path))
    return {row["label"]: np.mean([s["pybullet_fallen"] for s in row["samples"]], axis=0)
            for row in data["rows"] if row["kind"] != "mechanics" and row["samples"]}


def mujoco_p_fall(path: str) -> dict[str, np.ndarray]:
    return {label: np.asarray(v["mujoco"], float) for label, v in json.load(open(path))["p_fall"].items()}


def _named(values: list[str]) -> list[tuple[str, str]]:
    pairs = []
    for value in values:
        name, sep, path = value.partition("=")
        if not sep:
            raise SystemExit(f"--pybullet/--mujoco take NAME=FILE, got {value!r}")
        pairs.append((name, path))
    return pairs


def table(runs: dict[str, dict[str, np.ndarray]]) -> str:
    names = list(runs)
    labels = [label for label in next(iter(runs.values())) if all(label in r for r in runs.values())]
    lines = ["| row | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for label in labels:
        lines.append(f"| {label} | " + " | ".join(" ".join(f"{v:.2f}" for v in runs[n][label]) for n in names) + " |")
    lines += ["", "Mean |dP(falls)| over the rows' objects:", "",
              "| | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for a in names:
        cells = []
        for b in names:
            dp = [float(np.mean(np.abs(runs[a][label] - runs[b][label]))) for label in labels]
            cells.append("" if a == b else f"{np.mean(dp):.3f}")
        lines.append(f"| {a} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pybullet", action="append", default=[], help="NAME=export.json")
    parser.add_argument("--mujoco", action="append", default=[], help="NAME=mujoco_run --json result")
    parser.add_argument("--md", default=None)
    args = parser.parse_args()
    runs = {name: pybullet_p_fall(path) for name, path in _named(args.pybullet)}
    runs |= {name: mujoco_p_fall(path) for name, path in _named(args.mujoco)}
    if len(runs) < 2:
        raise SystemExit("give at least two runs")
    report = table(runs)
    print(report)
    if args.md:
        open(args.md, "w").write(report)


if __name__ == "__main__":
    main()
