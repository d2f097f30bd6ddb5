"""``ipe_node``: the intuitive physics engine as a ROS 2 node.

Executor callbacks only convert messages (``msg_bridge``) and hand scenes to the ROS-free
:class:`~ipe_ros.service.PredictionService`, whose own thread runs the Monte Carlo samples in worker
processes and calls back here to publish. Topics, the service and parameters are listed in README.md.
"""

from __future__ import annotations

import collections
import sys
import time
from typing import Any, Callable

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.service import Service as RclpyService
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64, String
from std_srvs.srv import Trigger
from geometry_msgs.msg import Vector3Stamped
from visualization_msgs.msg import MarkerArray

from msg_bridge.ask_json import id_of, parse_request, question_from_data, request_id_of, support_graph_markers
from msg_bridge.json_text import answer_to_string, scene_name_of, string_to_scene
from msg_bridge.markers import markers_to_scene, scene_to_markers
from msg_bridge.prediction_markers import prediction_to_markers
from msg_bridge.outputs import fall_direction_msg, fall_fraction_msg, fall_probability_msg
from msg_bridge.stamps import header_to_stamp_ns

from ..engine import ConfigError
from ..engine.plugins import load_plugins
from ..engine.scene.meshes import NotYetDecomposed
from .evidence import EvidenceInterface
from .observe import ObserveInterface
from ..engine.errors import clip
from ..service import (Answer, NoSceneError, PredictionFailed, PredictionService, QuestionService, ServiceConfig,
                       StampedScene, error_answer, refusal_answer)
from ..service.decompositions import DecompositionService
from .mesh_wait import MeshWaitInterface
from . import params
from .diagnostics import diagnostics_msg
from .executor import SubmitOnceExecutor
from .process_setup import return_large_buffers_to_the_system, unusable_dds_profile_file, use_node_dds_profiles

#: Outputs are "latched": reliable + transient-local, depth 1, so a late joiner gets the latest answer.
LATCHED_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
INPUT_QOS = QoSProfile(depth=5, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
#: Questions are never dropped in our reader (every question gets exactly one reply): a flood is
#: held back by reliable flow control instead of overwritten, and each one is answered "busy" at once.
ASK_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
#: Replies to questions: latched like the other outputs, deep enough that a burst of "busy" replies
#: is not overwritten before it is delivered (a late joiner gets the latest ones; match them by id).
ANSWER_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: The scene subscriptions per ``scene_reliability``: "both" accepts reliable and sensor-style publishers.
SCENE_QOS = {"both": (ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT),
             "reliable": (ReliabilityPolicy.RELIABLE,), "best_effort": (ReliabilityPolicy.BEST_EFFORT,)}
#: How many recent scene messages are remembered to use each once (a few seconds of a 10 Hz stream).
DUPLICATE_WINDOW = 64
DIAGNOSTICS_PERIOD_S = 1.0
#: Refused inputs logged per second at most (each is still answered and counted).
REFUSAL_LOG_LINES_PER_S = 5


class IpeInterface(ObserveInterface, EvidenceInterface, MeshWaitInterface):
    """The node's topics, service and prediction service, shared by :class:`IpeNode` (starts
    answering at once) and :class:`IpeLifecycleNode` (configure starts the workers, activate starts
    answering; ros/lifecycle.py). Mixed into an rclpy ``Node``."""

    service: PredictionService | None = None
    questions: QuestionService | None = None

    def _declare(self) -> dict[str, Any]:
        self._values = params.declare_all(self)
        self._inputs: list = []  # subscriptions, service and timer of the answering state
        # per input (handler name): the samples delivered lately, so that the other reliability's copy is skipped
        self._recently_seen: dict[str, collections.deque] = collections.defaultdict(
            lambda: collections.deque(maxlen=DUPLICATE_WINDOW))
        self._refusal_log_window_s, self._refusal_log_lines, self._refusals_not_logged = -1.0, 0, 0
        self.add_on_set_parameters_callback(self._on_set_parameters)
        return self._values

    def _open(self, start_method: str) -> ServiceConfig:
        """Publishers and the prediction service (its worker processes start here)."""
        values = self._values
        config = params.config_from_values(values)  # bad overrides end here with a named error
        self._publishers = [
            self.create_publisher(String, "~/prediction", LATCHED_QOS),
            self.create_publisher(Float64, "~/fall_fraction", LATCHED_QOS),
            self.create_publisher(Float64, "~/fall_probability", LATCHED_QOS),
            self.create_publisher(Vector3Stamped, "~/fall_direction", LATCHED_QOS),
            self.create_publisher(MarkerArray, "~/markers", LATCHED_QOS),
            self.create_publisher(DiagnosticArray, "/diagnostics", 10),
            self.create_publisher(String, "~/answer", ANSWER_QOS),
            self.create_publisher(MarkerArray, "~/support_graph", LATCHED_QOS),
            self.create_publisher(MarkerArray, "~/perceived_scene", LATCHED_QOS),
        ]
        (self._pub_prediction, self._pub_fraction, self._pub_probability, self._pub_direction, self._pub_markers,
         self._pub_diagnostics, self._pub_answer, self._pub_support_graph, self._pub_perceived) = self._publishers
        pool = None
        if str(values["dask_scheduler"]).strip():
            from ..engine.compute.cluster import DaskMap  # only a node that offloads to a cluster needs dask

            try:
                pool = DaskMap(str(values["dask_scheduler"]).strip())
            except ConfigError as exc:
                raise ConfigError("dask_scheduler", exc.problem) from None
        self.service = PredictionService(config, workers=int(values["workers"]), publish=self._publish_answer,
                                         log_error=self._log_error, log_info=self._log_info,
                                         start_method=start_method, publish_error=self._publish_error, pool=pool)
        self.questions = QuestionService(self.service, publish=self._publish_question_answer,
                                         log_error=self._log_error)
        self.decompositions = DecompositionService(log_error=self._log_error, log_info=self._log_info)
        self._diagnostics_timer = self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics,
                                                    callback_group=MutuallyExclusiveCallbackGroup())
        self.service.start()
        self.questions.start()
        self.decompositions.start()
        self._open_observations(LATCHED_QOS)
        return config

    def _listen(self) -> None:
        """Start answering: the scene and question subscriptions and the Trigger service."""
        # Inputs and the service in separate groups: a service call waiting for its answer never
        # holds up scene intake or the 1 Hz health report (with a multi-threaded executor).
        inputs = MutuallyExclusiveCallbackGroup()
        self._subscribe_per_reliability("scene_reliability", INPUT_QOS.depth, inputs, (
            (MarkerArray, "~/scene", self._on_markers), (String, "~/scene_json", self._on_scene_json)))
        self._inputs.append(self.create_subscription(String, "~/ask", self._on_ask, ASK_QOS, callback_group=inputs))
        self._inputs.append(self.create_subscription(String, "~/observe", self._on_observe, ASK_QOS,
                                                     callback_group=inputs))
        self._subscribe_evidence(inputs)  # the perception sources' topics (depth's camera)
        self._inputs.append(self.create_service(Trigger, "~/predict", self._on_predict,
                                                callback_group=MutuallyExclusiveCallbackGroup()))
        config = self.service.config
        self.get_logger().info(
            f"ready: k = {config.request.model.samples}, sigma = {config.request.model.sigma_m:g} m, "
            f"phi = {config.request.model.phi_m_s2[0]:g} m/s^2, preset {config.request.settings.name}, "
            f"{self._values['workers']} worker(s); scenes on {self.resolve_topic_name('~/scene')} and "
            f"{self.resolve_topic_name('~/scene_json')}")

    def _subscribe_per_reliability(self, setting: str, depth: int, group, streams) -> None:
        """One subscription per reliability the parameter ``setting`` names (``SCENE_QOS``), for each
        (message type, topic, handler) of ``streams``; a message both deliver is handled once."""
        for reliability in SCENE_QOS[str(self._values[setting])]:
            qos = QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST, reliability=reliability)
            # a reliable subscription does not match best-effort publishers: expected, not worth a warning
            quiet = SubscriptionEventCallbacks(incompatible_qos=lambda _event: None)
            for msg_type, topic, handler in streams:
                self._inputs.append(self.create_subscription(msg_type, topic, self._once(handler), qos,
                                                             callback_group=group, event_callbacks=quiet))

    def _unlisten(self) -> None:
        for entity in self._inputs:
            if isinstance(entity, RclpyService):
                self.destroy_service(entity)
            else:
                self.destroy_subscription(entity)
        self._inputs.clear()

    def _close_services(self, reason: str = "the node is shutting down") -> bool:
        """End the question and prediction services and their workers, answering what is waiting or
        in flight with an error naming ``reason``; False when none was open."""
        # both stop taking work first; the pool's close then ends whatever a question thread waits on,
        # so the two never wait one after the other (that took shutdown past 2 s mid-question)
        if self.decompositions is not None:  # inputs waiting on a mesh hear why (the publishers still stand)
            self.decompositions.close(reason=reason)
            self.decompositions = None
        if self.questions is not None:
            self.questions.close(reason=reason, join=False)
        if self.observations is not None:
            self.observations.close(reason=reason, join=False)
        opened = self.service is not None
        if opened:
            self.service.close(reason=reason)
        for job in (self.questions, self.observations):
            if job is not None:
                job.join(0.5)
        self.service = self.questions = self.observations = None
        return opened

    def _close(self, reason: str) -> None:
        """Stop answering, end the services and their workers, drop the publishers (the node lives on)."""
        self._unlisten()
        if self._close_services(reason):
            self.destroy_timer(self._diagnostics_timer)
            for publisher in self._publishers:
                self.destroy_publisher(publisher)

    # -- logging: whatever text an input carried, the logger gets printable text ----------------
    def _log_error(self, text: str) -> None:
        self.get_logger().error(clip(text, 2000))

    def _log_refusal(self, text: str) -> None:
        """A refused input, logged at most REFUSAL_LOG_LINES_PER_S times a second: rclpy's logger
        costs ~5 ms a line (it inspects the caller's frames), so a flood of bad inputs logged line
        by line would hold up every reply. Lines left out are counted in the next one."""
        now = time.monotonic()
        if now - self._refusal_log_window_s >= 1.0:
            self._refusal_log_window_s, self._refusal_log_lines = now, 0
        if self._refusal_log_lines >= REFUSAL_LOG_LINES_PER_S:
            self._refusals_not_logged += 1
            return
        self._refusal_log_lines += 1
        skipped, self._refusals_not_logged = self._refusals_not_logged, 0
        self._log_error(text + (f" ({skipped} refusals before this one not logged: too many)" if skipped else ""))

    def _log_info(self, text: str) -> None:
        self.get_logger().info(clip(text, 2000))

    # -- parameters ----------------------------------------------------------------------------
    def _on_set_parameters(self, changed: list[rclpy.parameter.Parameter]) -> SetParametersResult:
        values = dict(self._values)
        values.update({p.name: p.value for p in changed})
        try:
            config = params.config_from_values(values)
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self._values = values
        if self.service is not None:  # a lifecycle node not yet configured takes the values at configure
            self.service.update_config(config)
        return SetParametersResult(successful=True)

    # -- inputs ----------------------------------------------------------------------------------
    def _reject(self, topic: str, exc: Exception, scene_id: str, stamp_ns: int, frame_id: str) -> None:
        """Count, log and answer a refused scene: its client hears why on ~/prediction, as for a failed prediction."""
        reason = clip(str(exc), 1000)
        self.service.reject(reason)
        self._log_refusal(f"rejected scene on {topic}: {reason}")
        self._pub_prediction.publish(answer_to_string(refusal_answer(reason, clip(scene_id, 128), stamp_ns,
                                                                     clip(frame_id, 256), topic)))

    def _accept(self, scene, stamp_ns: int, frame_id: str) -> None:
        name = scene.name
        scene, learned = self.observations.learned.apply(scene) if self.observations is not None else (scene, ())
        item = StampedScene(scene=scene, stamp_ns=stamp_ns, frame_id=frame_id, scene_id=name,
                            seq=self.service.next_seq(), received_monotonic_s=time.monotonic(), learned=learned)
        if self.service.submit(item):
            self.get_logger().debug("a waiting scene was replaced by a newer one (keep-latest)")

    def _once(self, handler: Callable[[Any], None]) -> Callable[[Any, dict], None]:
        """``handler`` for a scene or camera subscription, skipping a message the other reliability's
        subscription already delivered (a reliable publisher reaches both). A sample is identified
        by its writer's timestamp and sequence number; the inputs group runs one callback at a time."""
        def deliver(msg: Any, info: dict) -> None:
            key = (info.get("source_timestamp"), info.get("publication_sequence_number"), type(msg).__name__)
            seen = self._recently_seen[handler.__name__]
            if key[0] is not None and key in seen:
                return
            seen.append(key)
            handler(msg)
        return deliver

    def _on_markers(self, msg: MarkerArray) -> None:
        try:
            converted = markers_to_scene(msg, max_objects=self.service.config.max_objects,
                                         meshes=self.service.config.meshes)
            self.service.check(converted.scene, converted.frame_id, "header.frame_id")
        except Exception as exc:  # noqa: BLE001 - no input may end the node; name what happened
            header = msg.markers[0].header if msg.markers else None
            where = (self.resolve_topic_name("~/scene"), "",
                     header_to_stamp_ns(header) if header is not None else self.get_clock().now().nanoseconds,
                     header.frame_id if header is not None else "")
            if isinstance(exc, NotYetDecomposed):
                self._scene_waits_for_mesh(exc, lambda: self._on_markers(msg), *where)
                return
            if not isinstance(exc, ValueError):  # SceneError / ConfigError name the field
                exc = RuntimeError(f"unreadable input ({type(exc).__name__})")
            self._reject(where[0], exc, *where[1:])
            return
        self._accept(converted.scene, converted.stamp_ns, converted.frame_id)

    def _on_scene_json(self, msg: String) -> None:
        try:
            scene = string_to_scene(msg, max_objects=self.service.config.max_objects,
                                    meshes=self.service.config.meshes)
            self.service.check(scene)  # frame_id (the parameter) is checked against the frames at configuration
        except Exception as exc:  # noqa: BLE001 - no input may end the node; name what happened
            where = (self.resolve_topic_name("~/scene_json"), scene_name_of(msg), self.get_clock().now().nanoseconds,
                     str(self._values["frame_id"]))
            if isinstance(exc, NotYetDecomposed):
                self._scene_waits_for_mesh(exc, lambda: self._on_scene_json(msg), *where)
                return
            if not isinstance(exc, ValueError):
                exc = RuntimeError(f"data: unreadable input ({type(exc).__name__})")
            self._reject(where[0], exc, *where[1:])
            return
        self._accept(scene, self.get_clock().now().nanoseconds, str(self._values["frame_id"]))

    def _on_ask(self, msg: String) -> None:
        """A question about an action: answered on ~/answer (with its id), never blocking intake. Its
        JSON is read once, then routed: ``infer`` to the observations, the others to the questions."""
        try:
            data = parse_request(msg)
        except ValueError as exc:  # unread (too large, not JSON): its id read only to echo it
            self._refuse_question(request_id_of(msg), str(exc))
            return
        request_id = id_of(data)
        if data.get("question") == "infer":
            self._ask_infer(data, request_id)
            return
        self._ask(data, request_id)

    def _ask(self, data: dict, request_id: str) -> None:
        """A question read from its JSON: queued, or refused; one whose scene holds a mesh not yet
        decomposed hears so (``"final": false``) and is asked again once it is."""
        try:
            question, scene = question_from_data(data, max_objects=self.service.config.max_objects,
                                                 meshes=self.service.config.meshes)
            source = None
            if scene is not None:
                source = StampedScene(scene=scene, stamp_ns=self.get_clock().now().nanoseconds,
                                      frame_id=str(self._values["frame_id"]), scene_id=scene.name)
            refused = self.questions.submit(question, source)
        except NotYetDecomposed as pending:
            refused = self._question_waits_for_mesh(pending, data, request_id)
        except ValueError as exc:
            refused = str(exc)
        except Exception as exc:  # noqa: BLE001 - no input may end the node
            refused = f"data: unreadable question ({type(exc).__name__})"
        if refused is not None:
            self._refuse_question(request_id, refused)

    def _refuse_question(self, request_id: str, refused: str) -> None:
        self._log_refusal(f"question {request_id!r} refused: {refused}")
        self._pub_answer.publish(answer_to_string({"id": request_id, "final": True, "error": clip(refused, 1000)}))

    def _publish_question_answer(self, message: dict, source: StampedScene) -> None:
        self._pub_answer.publish(answer_to_string(message))
        if message.get("question") == "support" and "answer" in message:
            self._pub_support_graph.publish(support_graph_markers(source.scene, message["answer"], source.frame_id,
                                                                  source.stamp_ns))

    # -- service -----------------------------------------------------------------------------------
    def _on_predict(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        try:
            answer = self.service.predict_latest(float(self._values["service_timeout_s"]))
        except (NoSceneError, PredictionFailed, TimeoutError) as exc:
            response.success, response.message = False, clip(str(exc), 1000)
            return response
        response.success, response.message = True, answer_to_string(answer.to_dict()).data
        return response

    # -- outputs (called from the prediction thread) ----------------------------------------------------
    def _publish_answer(self, answer: Answer) -> None:
        source, prediction = answer.source, answer.prediction
        self._pub_prediction.publish(answer_to_string(answer.to_dict()))
        fraction = fall_fraction_msg(prediction)
        if fraction is not None:
            self._pub_fraction.publish(fraction)
        probability = fall_probability_msg(prediction)
        if probability is not None:
            self._pub_probability.publish(probability)
        direction = fall_direction_msg(prediction, source.frame_id, source.stamp_ns)
        if direction is not None:  # a zero vector means "nothing falls"
            self._pub_direction.publish(direction)
        self._pub_markers.publish(prediction_to_markers(source.scene, prediction, source.frame_id, source.stamp_ns))
        if answer.perceived_scene is not None:  # in ~/scene's own format: a robot can re-publish it
            self._pub_perceived.publish(scene_to_markers(answer.perceived_scene, source.frame_id, source.stamp_ns))
        outcome = ", ".join(f"{label} {value:.3f}" for label, value in (
            ("fall fraction", prediction.fall_fraction), ("P(anything falls)", prediction.any_fall_probability))
            if value is not None) or "answered"
        self._log_info(
            f"{source.scene_id} #{source.seq}: {outcome}, k = {prediction.samples}"
            f"{f' ({prediction.failed_samples} failed)' if prediction.failed_samples else ''}, "
            f"{answer.compute_s:.2f} s" + (f", {answer.rrd_path}" if answer.rrd_path else ""))

    def _publish_error(self, source: StampedScene, error: str) -> None:
        self._pub_prediction.publish(answer_to_string(error_answer(source, clip(error, 1000))))

    def _publish_diagnostics(self) -> None:
        stats = self.service.stats()
        name = self.get_fully_qualified_name()  # namespaced: two nodes never share a status name
        meshes = self.decompositions.status() if self.decompositions is not None else None
        self._pub_diagnostics.publish(diagnostics_msg(stats, f"{name}: IPE prediction service",
                                                      self.get_clock().now().nanoseconds, name, meshes))



class IpeNode(IpeInterface, Node):
    """Subscribes to scenes, predicts in worker processes, publishes answers: from construction on."""

    def __init__(self, node_name: str = "ipe", *, start_method: str = "forkserver", **node_kwargs: Any):
        super().__init__(node_name, **node_kwargs)
        self._declare()
        self._open(start_method)
        self._listen()

    def destroy_node(self) -> None:
        self._close_services()  # the node's own teardown destroys every entity
        super().destroy_node()


def main(args: list[str] | None = None, node_class: type = IpeNode) -> int:
    """Entry point of ``ipe_node`` / ``ros2 run ipe_ros ipe_node``; SIGINT and SIGTERM end it cleanly."""
    unusable = unusable_dds_profile_file()
    if unusable is not None:  # Fast DDS would wait on it for ever, silently, inside rclpy.init
        print(f"ipe_node: error: {unusable}", file=sys.stderr)
        return 2
    use_node_dds_profiles()
    return_large_buffers_to_the_system()
    # installed packages' queries and perceptions, before the parameters that offer them are declared
    load_plugins(lambda problem: print(f"ipe_node: warning: {problem}", file=sys.stderr))
    rclpy.init(args=args)  # installs SIGINT/SIGTERM handlers that shut the context down
    node = None
    code = 0
    try:
        node = node_class()
        executor = SubmitOnceExecutor(num_threads=4)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ConfigError, ValueError, InvalidParameterValueException, InvalidParameterTypeException) as exc:
        print(f"ipe_node: error: {exc}", file=sys.stderr)  # a bad -p override: one line, exit 2
        code = 2
    except Exception:  # noqa: BLE001
        # SIGTERM's handler shuts the context down under the executor's feet: its next wait fails.
        # That is a clean stop; anything while the context is still up is a real error.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
