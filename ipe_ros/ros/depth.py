"""The depth camera's inputs (``~/depth/image``, ``~/depth/camera_info``, ``~/depth/camera_pose``):
the newest image kept with its camera for the next scene's depth perception; mixed into the node's
interface (ros/node.py)."""

from __future__ import annotations

from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image

from msg_bridge.depth import camera_info_to_dict, image_to_depth_m, pose_to_tuples
from msg_bridge.stamps import header_to_stamp_ns

from ..engine import ConfigError
from . import params


class DepthInterface:
    """Mixed into ``IpeInterface``: the depth camera's handlers (subscribed in ``_listen``; the newest
    CameraInfo and pose are the node's ``_camera_info`` and ``_camera_pose``)."""

    def _on_camera_info(self, msg: CameraInfo) -> None:
        self._camera_info = camera_info_to_dict(msg)

    def _on_camera_pose(self, msg: PoseStamped) -> None:
        try:
            position, orientation, frame, _ = pose_to_tuples(msg)
        except ValueError as exc:
            self._log_refusal(f"refused camera pose on {self.resolve_topic_name('~/depth/camera_pose')}: {exc}")
            return
        self._camera_pose = (position, orientation, frame)

    def _on_depth_image(self, msg: Image) -> None:
        """A depth image for depth perception: kept (the newest) with its camera, for the next scene."""
        from ..engine.vision.camera import camera_from_info
        from ..engine.vision.depth import DepthObservation

        topic = self.resolve_topic_name("~/depth/image")
        fixed = params.camera_pose(self._values)
        pose = (*fixed, str(self._values["frame_id"])) if fixed is not None else self._camera_pose
        try:
            if self._camera_info is None:
                raise ConfigError("camera_info", "no CameraInfo received yet on ~/depth/camera_info")
            if pose is None:
                raise ConfigError("camera_pose", "no camera pose yet: publish ~/depth/camera_pose or set "
                                                 "depth.camera_pose")
            camera = camera_from_info(self._camera_info, pose[0], pose[1])
            observation = DepthObservation(camera, image_to_depth_m(msg))
        except ValueError as exc:
            self.service.refuse_depth()
            self._log_refusal(f"refused depth image on {topic}: {exc}")
            return
        self.service.set_depth(observation, header_to_stamp_ns(msg.header), pose[2])
