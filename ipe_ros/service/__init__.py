"""Prediction as a service, without ROS: a keep-latest scene slot, one prediction thread, the pool;
questions beside it; recordings. One job per module: values.py (config, answers, counters, errors),
predictions.py (PredictionService), questions.py (QuestionService), recording.py (the .rrd files).

The ROS node (``ipe_ros.ros.node``) only converts messages and hands scenes to :class:`PredictionService`;
everything that takes time happens here, off the executor:

* ``submit`` stores a scene in a one-slot queue. A newer scene replaces one still waiting (the
  replaced one is counted as ``dropped``): a robot wants the answer for the world as it is now,
  not for a backlog.
* One prediction thread takes the waiting scene, runs the Monte Carlo IPE in the worker pool,
  optionally writes a rerun ``.rrd``, and calls ``publish(answer)``. One prediction is in flight
  at a time: the pool already uses every core for the k samples of one scene, so a second
  prediction would only make both slower.
* ``predict_latest`` (the Trigger service) waits for an answer on the newest scene with the current
  config, reusing the last answer when it is already that.
* A worker that dies is replaced by the pool and its samples are run again; samples lost twice
  are counted as failed in the answer (``failed_samples``), never silently dropped.
"""

from .predictions import PredictionService
from .questions import DEFAULT_QUESTION_SAMPLES, MAX_WAITING_QUESTIONS, QuestionCancelled, QuestionService
from .values import (RECENT_EVENTS, Answer, NoSceneError, PredictionFailed, ServiceConfig, ServiceStats, StampedScene,
                     decomposing_answer, error_answer, refusal_answer, stamp_dict)

__all__ = ["Answer", "DEFAULT_QUESTION_SAMPLES", "MAX_WAITING_QUESTIONS", "NoSceneError", "PredictionFailed",
           "PredictionService", "QuestionCancelled", "QuestionService", "RECENT_EVENTS", "ServiceConfig", "ServiceStats",
           "StampedScene", "decomposing_answer", "error_answer", "refusal_answer", "stamp_dict"]
