"""``python -m ipe_ros.viz.stream_to_viewer URL RRD RECORDING_ID TIMEOUT_S``: send a written ``.rrd`` to
a running rerun viewer, in a process of its own.

rerun's gRPC client waits for a viewer that does not answer: a flush without bound, a disconnect ~5 s
while holding the interpreter, and the process's exit until the connection gives up (24 s measured
against a peer that accepts and stays silent). In the node's own process that stalled answers and
shutdown; here it can only stall this helper, which ends itself after ``TIMEOUT_S`` whatever the
viewer does (``os._exit``: no exit handler waits on the connection).
"""

from __future__ import annotations

import os
import sys


def main(argv: list[str]) -> int:
    url, path, recording_id, timeout_s = argv[0], argv[1], argv[2], float(argv[3])
    code = 1
    try:
        import rerun as rr

        from .rerun_log import APPLICATION_ID

        rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
        rec.set_sinks(rr.GrpcSink(url))
        rec.log_file_from_path(path)
        rec.flush(timeout_sec=timeout_s)
        code = 0
    except Exception as exc:  # noqa: BLE001 - report in one line; the recording file is unaffected
        print(f"ipe: streaming {path} to the viewer at {url} failed: {str(exc)[:300]}", file=sys.stderr)
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    main(sys.argv[1:])
