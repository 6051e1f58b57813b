"""Paths and atomic file writes.

Every writer in :mod:`kubric.file_io` encodes its whole file in memory and then calls
:func:`atomic_write_bytes`: the bytes go to a hidden temporary file in the *same* directory
(``.<name>.<unique>.tmp``), which is then renamed over the final name with :func:`os.replace`
(atomic on POSIX and Windows within one file system). A crash or an exception while writing
therefore never leaves a truncated file under the final name; at worst a hidden ``.tmp`` file.
The data is not fsync'ed (atomic with respect to process crashes, not to power loss).
"""

from __future__ import annotations

import os
import pathlib
import uuid

PathLike = str | os.PathLike

TEMP_SUFFIX = ".tmp"


def as_path(path: PathLike) -> pathlib.Path:
    """Return ``path`` (a ``str`` or any ``os.PathLike``) as a :class:`pathlib.Path`.

    ``~`` is not expanded and the path is not resolved: the value is only converted.
    """
    if isinstance(path, pathlib.Path):
        return path
    if isinstance(path, str | os.PathLike):
        fs_path = os.fspath(path)
        if isinstance(fs_path, bytes):
            raise TypeError(f"as_path: bytes paths are not supported, got {path!r}")
        if not fs_path:
            raise ValueError("as_path: the path must not be empty")
        return pathlib.Path(fs_path)
    raise TypeError(
        f"as_path: expected a str or os.PathLike (e.g. pathlib.Path), got {type(path).__name__} "
        f"{path!r}"
    )


def temp_name_for(path: pathlib.Path) -> pathlib.Path:
    """A unique hidden temporary name next to ``path`` (same directory → same file system)."""
    return path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:12]}{TEMP_SUFFIX}")


def atomic_write_bytes(data: bytes | bytearray | memoryview, filename: PathLike) -> pathlib.Path:
    """Write ``data`` to ``filename`` atomically; create missing parent directories.

    Returns the final path. The file gets the usual permissions (0o666 minus the umask).
    """
    path = as_path(filename)
    if path.is_dir():
        raise IsADirectoryError(f"cannot write file {str(path)!r}: it is an existing directory")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_name_for(path)
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
    try:
        with os.fdopen(fd, "wb") as fp:
            fp.write(data)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def read_bytes(filename: PathLike) -> bytes:
    """Read a whole file; the error names the path when it is missing."""
    path = as_path(filename)
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(f"no such file: {str(path)!r}") from None


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` still runs. A zombie (exited, not yet reaped — e.g. a worker of a
    killed runner in a container whose init does not reap orphans) counts as gone."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    if not pathlib.Path("/proc/self/stat").exists():
        return True  # no procfs (macOS): the signal-0 answer is all we know
    try:  # field 3 of /proc/PID/stat is the state; the name before it is in parentheses
        stat = pathlib.Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False  # gone meanwhile
    return stat.rsplit(")", 1)[-1].split()[0] != "Z"
