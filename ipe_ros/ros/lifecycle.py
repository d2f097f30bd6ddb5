"""``ipe_lifecycle_node``: the same node as a managed (lifecycle) node, its transitions guarded."""

from __future__ import annotations

from typing import Any

from lifecycle_msgs.srv import ChangeState, GetAvailableTransitions
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from ..engine import ConfigError
from .node import IpeInterface, main


class IpeLifecycleNode(IpeInterface, LifecycleNode):
    """The managed variant (``ipe_lifecycle_node``): unconfigured it only holds its parameters;
    configure starts the worker processes and publishers, activate starts answering (subscriptions
    and ``~/predict``), deactivate stops answering (workers stay warm), cleanup ends the workers."""

    def __init__(self, node_name: str = "ipe", *, start_method: str = "forkserver", **node_kwargs: Any):
        super().__init__(node_name, **node_kwargs)
        self._start_method = start_method
        self._declare()
        self._guard_transitions()

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self._open(self._start_method)
        except ConfigError as exc:
            self.get_logger().error(f"configure failed: {exc}")
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._listen()
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._unlisten()
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._close("the node was cleaned up (lifecycle cleanup)")
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._close("the node is shutting down (lifecycle shutdown)")
        return TransitionCallbackReturn.SUCCESS

    def _guard_transitions(self) -> None:
        """rclpy (7.1) lets the state machine raise on a transition not allowed from the current state,
        which ends the node without a reply. Wrap the ~/change_state service's callback (found
        through the public ``services`` and ``Service.callback``) so that such a request is refused
        instead (success false), the state kept; ~/get_available_transitions says what is allowed."""
        by_name = {service.srv_name.rpartition("/")[2]: service for service in self.services}
        change, available = by_name.get("change_state"), by_name.get("get_available_transitions")
        if change is None or available is None:  # the communication interface is off: nothing to guard
            return
        serve_change, list_transitions = change.callback, available.callback

        def guarded_change_state(request: ChangeState.Request, response: ChangeState.Response):
            transitions = list_transitions(GetAvailableTransitions.Request(),
                                           GetAvailableTransitions.Response()).available_transitions
            allowed = {t.transition.id: t.transition.label for t in transitions}
            label = request.transition.label  # asked by label (as rclpy reads it) or else by id
            asked = label or request.transition.id
            if asked not in (set(allowed.values()) if label else allowed):
                state = transitions[0].start_state.label if transitions else "finalized"
                self.get_logger().warning(
                    f"transition {asked} refused: not allowed from state '{state}' (allowed: "
                    + (", ".join(f"{label} ({tid})" for tid, label in sorted(allowed.items())) or "none") + ")")
                response.success = False
                return response
            return serve_change(request, response)

        change.callback = guarded_change_state

    def destroy_node(self) -> None:
        self._close_services()
        super().destroy_node()


def lifecycle_main(args: list[str] | None = None) -> int:
    """Entry point of ``ipe_lifecycle_node``: the managed node, waiting to be configured."""
    return main(args, IpeLifecycleNode)
