"""What the memory a process gained is held by: from a memray capture (``soak.py --memray FILE``), the
call stacks whose live bytes grew most between two moments (by default a third of the way in, after
warm-up, and the last snapshot before shutdown).

    .venv/bin/python benchmarks/memray_growth.py FILE [--from-fraction 0.33] [--top 25] [--depth 12]

memray (a dev tool, not a dependency: ``pip install memray``) follows native allocations, so what
rclpy, Fast DDS or numpy keep shows up with its C/C++ frames, not only what tracemalloc sees.
"""

from __future__ import annotations

import argparse
import collections

import memray


def _frames(record, depth: int) -> tuple[str, ...]:
    try:
        stack = record.hybrid_stack_trace(max_stacks=depth)
    except NotImplementedError:  # captured without --native
        stack = record.stack_trace(max_stacks=depth)
    return tuple(f"{func} {file.rsplit('/', 1)[-1]}:{line}" for func, file, line in stack)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("capture")
    parser.add_argument("--from-fraction", type=float, default=0.33,
                        help="the earlier moment, as a fraction of the capture's snapshots (after warm-up)")
    parser.add_argument("--top", type=int, default=25)
    parser.add_argument("--depth", type=int, default=12, help="frames shown per stack")
    args = parser.parse_args()
    reader = memray.FileReader(args.capture)
    snapshots = list(reader.get_memory_snapshots())
    if len(snapshots) < 3:
        raise SystemExit(f"{args.capture}: {len(snapshots)} memory snapshots; capture longer")
    first = int(len(snapshots) * args.from_fraction)
    # the last snapshot before the process began to shut down (its heap falls then)
    peak_rss = max(s.rss for s in snapshots[first:])
    last = max(i for i in range(first, len(snapshots)) if snapshots[i].rss >= 0.9 * peak_rss)
    t0, t1 = snapshots[first].time, snapshots[last].time
    print(f"{args.capture}: {len(snapshots)} snapshots; from #{first} (rss {snapshots[first].rss / 2**20:.1f} MB, "
          f"heap {snapshots[first].heap / 2**20:.1f} MB) to #{last} (rss {snapshots[last].rss / 2**20:.1f} MB, "
          f"heap {snapshots[last].heap / 2**20:.1f} MB), {(t1 - t0) / 1000:.0f} s apart")
    growth: dict[tuple[str, ...], list[int]] = collections.defaultdict(lambda: [0, 0, 0])
    records = reader.get_temporal_allocation_records(merge_threads=True)
    for record in records:
        before = after = count = 0
        for interval in record.intervals:
            start, end = interval.allocated_before_snapshot, interval.deallocated_before_snapshot
            live_at = lambda i: start <= i and (end is None or i < end)  # noqa: E731
            if live_at(first):
                before += interval.n_bytes
            if live_at(last):
                after += interval.n_bytes
                count += interval.n_allocations
        if after != before:
            entry = growth[_frames(record, args.depth)]
            entry[0] += after - before
            entry[1] += after
            entry[2] += count
    total = sum(v[0] for v in growth.values())
    print(f"live bytes gained by tracked allocations: {total / 2**20:.2f} MB\n")
    for stack, (gained, live, count) in sorted(growth.items(), key=lambda kv: -kv[1][0])[:args.top]:
        print(f"+{gained / 2**10:9.1f} KB (live {live / 2**10:.1f} KB in {count} allocations)")
        for frame in stack:
            print(f"      {frame}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
