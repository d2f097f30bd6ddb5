"""What the node's process sets up before ``rclpy.init``: Fast DDS's profiles (the node's own, and
no profile file Fast DDS would hang on), and glibc's handling of large buffers."""

from __future__ import annotations

import os
import stat
from pathlib import Path

#: the node's Fast DDS profiles (the file says why: payload memory that otherwise only grows)
FASTDDS_PROFILES = Path(__file__).with_name("fastdds_node.xml")
_PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")  # Fast DDS 2.x, 3.x
#: files Fast DDS reads at start-up besides: its environment file, and profiles in the working folder
_ENVIRONMENT_VARIABLE = "FASTDDS_ENVIRONMENT_FILE"
_DEFAULT_PROFILE_NAMES = ("DEFAULT_FASTRTPS_PROFILES.xml", "DEFAULT_FASTDDS_PROFILES.xml")
#: a profiles file is a few KB of XML
MAX_PROFILE_BYTES = 16 * 2**20


def unusable_dds_profile_file(environ=os.environ, folder: Path | None = None) -> str | None:
    """Why a file Fast DDS reads at start-up cannot be read (one line naming it and the fix), or None.
    Fast DDS opens it and reads it whole inside ``rclpy.init``: a FIFO there waits for a writer for
    ever, a device reads without end, and nothing is said. A missing file is Fast DDS's to report."""
    named = [(name, environ[name]) for name in (*_PROFILE_VARIABLES, _ENVIRONMENT_VARIABLE) if environ.get(name)]
    here = Path.cwd() if folder is None else folder
    named += [(f"{file} in the working folder", str(here / file)) for file in _DEFAULT_PROFILE_NAMES]
    for what, path in named:
        try:
            info = os.stat(path)  # follows a link, as Fast DDS does; never opens it
        except (OSError, ValueError):
            continue
        kind = ("a FIFO" if stat.S_ISFIFO(info.st_mode) else "a folder" if stat.S_ISDIR(info.st_mode)
                else "a device" if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode)
                else "a socket" if stat.S_ISSOCK(info.st_mode) else None)
        if kind is not None:
            return (f"{what}: {path} is {kind}, not a file (Fast DDS would wait on it for ever at start-up); "
                    "point it at a profiles XML file, or unset it")
        if info.st_size > MAX_PROFILE_BYTES:
            return f"{what}: {path} holds {info.st_size} bytes, not a profiles XML file; point it at one, or unset it"
    return None


def use_node_dds_profiles(environ=os.environ) -> bool:
    """Point Fast DDS at the node's profiles (before ``rclpy.init``), unless the environment chose
    profiles of its own or another middleware; whether it did."""
    if environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") not in ("rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp"):
        return False
    if any(name in environ for name in (*_PROFILE_VARIABLES, "RMW_FASTRTPS_USE_QOS_FROM_XML")):
        return False
    environ.update({name: str(FASTDDS_PROFILES) for name in _PROFILE_VARIABLES})
    environ["RMW_FASTRTPS_USE_QOS_FROM_XML"] = "1"  # else rmw_fastrtps sets its own memory policy
    return True


#: glibc's mallopt parameter for the size from which a buffer is mmapped (and unmapped when freed)
_M_MMAP_THRESHOLD = -3


def return_large_buffers_to_the_system(environ=os.environ, threshold_bytes: int = 128 * 1024) -> bool:
    """Keep glibc's mmap threshold fixed (unless the environment sets it): glibc raises it each time
    a large buffer is freed (up to 32 MB), after which the node's 1-2 MB messages come from the heap,
    which fragments and does not shrink; fixed, they are mmapped and returned to the system when
    freed. Whether it was set (False where the C library is not glibc)."""
    if "MALLOC_MMAP_THRESHOLD_" in environ:
        return False
    try:
        import ctypes

        return bool(ctypes.CDLL(None).mallopt(_M_MMAP_THRESHOLD, threshold_bytes))
    except (OSError, AttributeError):
        return False
