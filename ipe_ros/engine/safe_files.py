"""Files a cache keeps, read and written so that nothing planted in its folder reaches outside it:
the result store's entries (``compute/store.py``) and the meshes' convex parts (``scene/meshes.py``).

The folder is opened without following a link; each entry is opened relative to it, without
following a link and without blocking (a FIFO), checked to be a regular file, and read bounded;
an entry is written to a temporary file created anew (never an existing file or a link), then
renamed over its name (atomic: a crash leaves a ``.part``, never half an entry).
"""

from __future__ import annotations

import os
import secrets
import stat
from pathlib import Path


def is_folder(path: Path) -> bool:
    """Whether ``path`` is a folder; False, not an OSError, for a name too long or otherwise unusable
    (``Path.is_dir`` raises for a name past the file system's limit)."""
    try:
        return path.is_dir()
    except (OSError, ValueError):
        return False


class UnreadableFile(Exception):
    """A file named by an input is not one to read (missing, not a regular file, too large: then
    ``too_large``): the message says which, for the caller to name its field."""

    def __init__(self, message: str, too_large: bool = False):
        super().__init__(message)
        self.too_large = too_large


def read_file_bounded(path: Path, max_bytes: int, what: str = "a file") -> bytes:
    """``path``'s bytes, never waiting on a FIFO or reading past ``max_bytes`` (a device, a file that
    grows): UnreadableFile naming ``path`` otherwise. Links are followed (the caller decided where
    a file may be read from)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError:
        raise UnreadableFile(f"{path}: no such file") from None
    except OSError as exc:
        raise UnreadableFile(f"{path}: cannot be read ({exc.strerror})") from None
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):
        os.close(fd)
        raise UnreadableFile(f"{path} is not a regular file (a folder, a FIFO or a device)")
    with os.fdopen(fd, "rb") as handle:
        if info.st_size > max_bytes:
            raise UnreadableFile(f"{path}: {info.st_size} bytes, more than the {max_bytes} {what} may have",
                                 too_large=True)
        content = handle.read(max_bytes + 1)
    if len(content) > max_bytes:
        raise UnreadableFile(f"{path} grew past the {max_bytes} bytes {what} may have while read", too_large=True)
    return content


class UnsafeEntry(Exception):
    """A cache's entry or folder is not what the cache writes (a link, a file, a FIFO, too large)."""


def open_folder(folder: Path, create: bool, owner: str = "the store") -> int | None:
    """A descriptor of ``folder`` opened without following a link (close it); None where it does
    not exist and ``create`` is false. UnsafeEntry where it is a link or a file."""
    if create:
        try:
            folder.mkdir(parents=True)
        except FileExistsError:
            pass
    try:
        return os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
    except FileNotFoundError:
        if create:
            raise
        return None
    except OSError:  # a link (ELOOP) or a file (ENOTDIR) where the folder belongs
        raise UnsafeEntry(f"its folder {folder} is not a folder of {owner} (a link or a file)") from None


def read_entry(folder_fd: int, name: str, max_bytes: int) -> bytes | None:
    """The entry ``name``'s bytes, or None where there is none; UnsafeEntry where it is not a
    regular file or holds more than ``max_bytes``."""
    try:  # a link could point anywhere: never followed; a FIFO would block: not waited on
        fd = os.open(name, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK, dir_fd=folder_fd)
    except FileNotFoundError:
        return None
    except OSError:
        raise UnsafeEntry("not a regular file (a link or a folder)") from None
    with os.fdopen(fd, "rb") as handle:
        info = os.fstat(handle.fileno())
        if not stat.S_ISREG(info.st_mode):
            raise UnsafeEntry("not a regular file (a link or a folder)")
        if info.st_size > max_bytes:
            raise UnsafeEntry(f"{info.st_size} bytes, more than the {max_bytes} an entry may have")
        data = handle.read(max_bytes + 1)  # bounded even if it grows meanwhile
    if len(data) > max_bytes:
        raise UnsafeEntry(f"more than the {max_bytes} bytes an entry may have")
    return data


def write_entry(folder_fd: int, name: str, data: bytes) -> None:
    """``data`` as the entry ``name``, through a temporary file created anew and renamed over it (a
    link planted at the name is replaced, not written through). UnsafeEntry where the temporary
    name is taken already (never opened); OSError where the folder cannot be written."""
    partial = f"{name}.{os.getpid()}.{secrets.token_hex(4)}.part"
    try:
        fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644, dir_fd=folder_fd)
    except FileExistsError as exc:
        raise UnsafeEntry(f"its temporary file {partial} exists already ({exc.strerror})") from None
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.replace(partial, name, src_dir_fd=folder_fd, dst_dir_fd=folder_fd)
    except BaseException:
        try:
            os.unlink(partial, dir_fd=folder_fd)
        except OSError:
            pass
        raise


def trim_folder(folder_fd: int, suffix: str, max_bytes: int, keep: str) -> int:
    """Remove the oldest (by modification time) regular files ending in ``suffix`` until those left
    hold at most ``max_bytes`` together; never ``keep`` (the entry just written), never a link, a
    folder or any other file. The number removed."""
    entries = []
    with os.scandir(folder_fd) as listing:
        for entry in listing:
            if not entry.name.endswith(suffix) or entry.name == keep:
                continue
            try:
                info = entry.stat(follow_symlinks=False)
            except OSError:
                continue
            if stat.S_ISREG(info.st_mode):
                entries.append((info.st_mtime_ns, entry.name, info.st_size))
    total = sum(size for _, _, size in entries)
    try:
        total += os.stat(keep, dir_fd=folder_fd, follow_symlinks=False).st_size
    except OSError:
        pass
    removed = 0
    for _, name, size in sorted(entries):
        if total <= max_bytes:
            break
        try:
            os.unlink(name, dir_fd=folder_fd)
        except OSError:
            continue
        total -= size
        removed += 1
    return removed

