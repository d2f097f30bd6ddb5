"""The paper's analyses at full size through Dask on this machine's LocalCluster, timed and resumable.

    .venv/bin/python benchmarks/full_size.py bump [--workers 2] [--resume runs/bump]
                                                  [--out benchmarks/results/experiments] [-- ARGS...]
    .venv/bin/python benchmarks/full_size.py fall -- --grid-samples 48

Starts a LocalCluster on 127.0.0.1 (processes, one thread each, its HTTP port a free one), runs
``ipe experiment NAME --scheduler ADDRESS --resume DIR --out OUT ARGS`` in this process, and writes
``OUT/NAME_full_size.json``: the command, wall time, samples computed in this run and read back from
``DIR``, and samples/s. Interrupted (Ctrl-C, SIGTERM), the cluster is closed and the same command
continues from what ``DIR`` holds; the wall time then covers this run only, and the JSON keeps the
earlier runs' too. ``kill -USR1 PID`` prints every thread's stack to stderr (to see what a run waits on).
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import os
import signal
import sys
import time
from datetime import date
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

REPO = Path(__file__).resolve().parents[1]


def stored_samples(folder: Path) -> int:
    """Results ResumableMap holds: one file per sample (every phi value of it)."""
    return sum(1 for _ in folder.glob("*/*.json")) if folder.is_dir() else 0


def _stop(signum, frame):
    raise KeyboardInterrupt(f"signal {signum}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("name", help="the experiment (fall, bump, ...)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--resume", default=None, help="results folder (default: runs/NAME)")
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "experiments"))
    argv = sys.argv[1:]
    ours, extra = (argv[:argv.index("--")], argv[argv.index("--") + 1:]) if "--" in argv else (argv, [])
    args = parser.parse_args(ours)  # after "--": more `ipe experiment` arguments
    resume = Path(args.resume or REPO / "runs" / args.name)
    signal.signal(signal.SIGTERM, _stop)  # close the cluster on the way out, as Ctrl-C does
    signal.signal(signal.SIGINT, _stop)  # also when started in the background, where SIGINT comes ignored
    faulthandler.register(signal.SIGUSR1, all_threads=True)  # `kill -USR1 PID`: where every thread is, on stderr

    from ipe_ros import cli
    from ipe_ros.engine.compute.cluster import local_cluster

    before = stored_samples(resume)
    with local_cluster(args.workers) as client:
        command = ["experiment", args.name, "--scheduler", client.cluster.scheduler_address, "--resume", str(resume),
                   "--out", args.out, *extra]
        start = time.perf_counter()
        interrupted = False
        try:
            status = cli.main(command)
        except KeyboardInterrupt:
            status, interrupted = 130, True
        wall_s = time.perf_counter() - start
    after = stored_samples(resume)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{args.name}_full_size.json"
    runs = json.loads(path.read_text())["runs"] if path.exists() else []
    shown = ["ipe", *command[:2], "--scheduler", "<LocalCluster on 127.0.0.1>", *command[4:]]
    runs.append({"date": date.today().isoformat(), "command": " ".join(shown), "workers": args.workers,
                 "finished": status == 0 and not interrupted, "wall_s": wall_s,
                 "samples_read_back": before, "samples_computed": after - before,
                 "samples_per_s": (after - before) / wall_s if wall_s > 0 else None})
    total_wall = sum(r["wall_s"] for r in runs)
    summary = {"experiment": args.name, "runs": runs, "total_wall_s": total_wall,
               "total_samples": after, "samples_per_s_overall": after / total_wall if total_wall else None}
    path.write_text(json.dumps(summary, indent=1) + "\n")
    print(f"{args.name}: {'finished' if runs[-1]['finished'] else 'interrupted'} after {wall_s / 60:.1f} min, "
          f"{after - before} samples computed ({before} read back); {path}", file=sys.stderr)
    return status


if __name__ == "__main__":
    raise SystemExit(main())
