"""The service's rerun recordings: one ``.rrd`` per prediction and per recorded question, named by
a running number; rerun is imported when recording is switched on, never otherwise, and a
recording's trouble never costs the answer."""

from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path
from typing import Callable

from ..engine.errors import clip
from .values import Answer, ServiceConfig, StampedScene


def file_safe(text: str, limit: int) -> str:
    """``text`` as a file-name part: letters, digits, - _ . kept, anything else _."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)[:limit]



def load_rerun_if_recording(config: ServiceConfig) -> None:
    """Import rerun when recording is (switched) on, not on the first answer (the import takes ~0.4 s);
    without recording rerun is never imported."""
    if config.rerun_save_dir is not None or config.rerun_connect_url is not None:
        importlib.import_module("ipe_ros.viz.rerun_log")



def record_prediction(answer: Answer, config: ServiceConfig, number: int, log_error: Callable[[str], None]) -> Answer:
    """Write recording ``number`` of a prediction; the answer says where, or why not."""
    from ..viz import rerun_log  # imported on first use: rerun is only needed when logging

    item = answer.source
    safe = file_safe(item.scene_id, 80)
    path = Path(config.rerun_save_dir) / f"ipe_{number:06d}_scene{item.seq}_{safe}.rrd"
    answer = dataclasses.replace(answer, rrd_path=str(path.resolve()),
                                 rollouts_logged=min(config.rerun_rollouts_logged, answer.prediction.samples))
    try:
        logged = rerun_log.write_prediction_rrd(path, item.scene, answer.prediction, answer=answer.to_dict(),
                                                stamp_ns=item.stamp_ns, rollouts_logged=config.rerun_rollouts_logged,
                                                connect_url=config.rerun_connect_url)
    except rerun_log.ViewerUnavailable as exc:  # the file is there; only the live view is missing
        error = clip(f"streaming to the viewer failed: {exc}; the recording is in {path}", 600)
        log_error(error)
        return dataclasses.replace(answer, rrd_error=error)
    except Exception as exc:  # noqa: BLE001 - logging trouble must not cost the answer
        error = clip(f"writing {path} failed: {exc}", 600)
        log_error(error)
        return dataclasses.replace(answer, rrd_path=None, rollouts_logged=0, rrd_error=error)
    return dataclasses.replace(answer, rollouts_logged=logged)


def record_question(config: ServiceConfig, question, source: StampedScene, answers, number: int,
                    log_error: Callable[[str], None]) -> str | None:
    """Write recording ``number`` of a question's variants; its path, or None when it failed."""
    from ..viz import rerun_log  # only needed when recording

    safe = file_safe(question.request_id, 60) or "question"
    path = Path(config.rerun_save_dir) / f"ask_{number:06d}_{question.kind}_{safe}.rrd"
    try:
        rerun_log.write_question_rrd(path, source.scene, answers, stamp_ns=source.stamp_ns)
    except Exception as exc:  # noqa: BLE001 - a recording's trouble must not cost the answer
        log_error(f"writing {path} failed: {exc}")
        return None
    return str(path.resolve())
