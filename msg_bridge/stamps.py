"""Stamps as integer nanoseconds since the epoch <-> ``std_msgs/Header`` (no rclpy needed)."""

from __future__ import annotations

from builtin_interfaces.msg import Time
from std_msgs.msg import Header

NS_PER_S = 1_000_000_000


def header_to_stamp_ns(header: Header) -> int:
    return int(header.stamp.sec) * NS_PER_S + int(header.stamp.nanosec)


def stamp_ns_to_time(stamp_ns: int) -> Time:
    if stamp_ns < 0:
        raise ValueError(f"stamp_ns: must be >= 0 (nanoseconds since the epoch), got {stamp_ns}")
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def stamp_ns_to_header(stamp_ns: int, frame_id: str) -> Header:
    return Header(stamp=stamp_ns_to_time(stamp_ns), frame_id=frame_id)
