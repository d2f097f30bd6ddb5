"""What a perception source needs to see, declared once, so that every door can fill it unedited.

A source that draws the k scenes from a posterior given evidence (depth images, detections, a
second camera) says here what that evidence is and how each door gets it, its inputs rows of the
table of inputs as every other input is (``engine.input_row.Input``):
- the command line: the source's options (``PerceptionSource.options``, rows with a flag; added
  to ``ipe predict`` and ``ipe ask``), which ``read`` turns into the evidence (files read, checked,
  errors naming the option);
- the node: ``topics`` it subscribes to for every registered source. Each message is converted when
  it arrives by ``receive`` (a ``"module:function"`` path, since the engine never imports message
  classes: the node resolves it, msg_bridge-style code does the conversion) and held, the newest per
  topic; ``assemble`` turns what is held into the evidence when a scene is predicted. Its own node
  parameters (``parameters``: rows with a parameter name) are declared with the node's, in
  config/ipe.yaml and ``ros2 param``, and ``check`` refuses bad values of them by name.

The source then runs its own chain inside ``predict``, on the prediction's workers, within
``budget_share`` of its budget (``perceptions.PerceptionSource.run``). No door branches on a
perception's name.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Mapping

from .input_row import Input


@dataclass(frozen=True)
class Held:
    """One topic's newest message as received: its converted value, its header's stamp and frame,
    and how many were held on that topic so far (the view's number)."""

    value: Any
    stamp_ns: int
    frame_id: str
    number: int


#: receive(msg, held, node_values) -> (value, frame_id): a message converted as it arrives, given
#: what the source's other topics hold (a depth image needs the camera's calibration and pose);
#: an error refuses it (counted, logged in one line; nothing held; the node goes on)
Receive = Callable[[Any, Mapping[str, Held], Mapping[str, Any]], tuple[Any, str]]


@dataclass(frozen=True)
class EvidenceTopic:
    """A node topic (relative name, e.g. ``~/depth/image``) of message type ``message_type``
    (``"sensor_msgs/msg/Image"``), converted by ``receive`` (``"module:function"``, a ``Receive``).
    ``what``: a message, as errors name it ("depth image"). ``counted_as``: its counter in
    /diagnostics (``<counted_as>``, ``<counted_as>_refused``; empty: not counted). ``view``: the
    evidence is this topic's newest message (its stamp and frame must match the scene's; a new one
    is a new view); the other topics only help receive it (a camera's calibration)."""

    name: str
    message_type: str
    receive: str
    what: str
    counted_as: str = ""
    view: bool = False


@dataclass(frozen=True)
class Evidence:
    """What a source needs and how each door fills it (the module docstring).

    what: the evidence, as errors name it ("the depth images").
    describes: what one piece of evidence is of ("one depth image describes one scene").
    read: the source's CLI option values (by field) -> the evidence.
    assemble: the views' held values (by topic name) -> the evidence.
    missing: what to publish, said when a scene comes before any view.
    frame_named: what the view's frame is the frame of ("the camera pose").
    max_age_parameter: the node parameter bounding a view's distance from the scene's stamp (s).
    reliability_parameter: the node parameter choosing the subscriptions' reliability
      (``scene_reliability`` when empty).
    parameters: the source's own node parameters (``Input`` rows with a parameter name).
    check: the node's parameter values -> None, or a ConfigError naming the parameter (run
      whenever parameters are set).
    budget_share: of a prediction's budget, what its chain may use (the samples get the rest).
    """

    what: str
    describes: str
    read: Callable[[Mapping[str, Any]], Any] | None = None
    topics: tuple[EvidenceTopic, ...] = ()
    assemble: Callable[[Mapping[str, Any]], Any] | None = None
    missing: str = ""
    frame_named: str = "the view"
    max_age_parameter: str = ""
    reliability_parameter: str = ""
    parameters: tuple[Input, ...] = ()
    check: Callable[[Mapping[str, Any]], None] | None = None
    budget_share: float = 0.5

    def views(self) -> tuple[EvidenceTopic, ...]:
        return tuple(t for t in self.topics if t.view)


def resolve(path: str) -> Callable:
    """``"module:function"`` -> the function (imported when first needed: the engine names message
    converters it must not import)."""
    import importlib

    module, _, name = path.partition(":")
    if not module or not name:
        raise ValueError(f"a converter is named 'module:function', got {path!r}")
    return getattr(importlib.import_module(module), name)
