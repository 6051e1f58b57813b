"""Paths and URLs alike: a small fsspec-aware layer for output roots and scene directories.

An output location is either a local path (``out/``, ``/data/run``) or an fsspec URL
(``s3://bucket/run``, ``gs://bucket/run``, ``memory://run``, ``file:///data/run``, ...).
Local paths never import fsspec; URLs import it lazily, with the protocol's package
(``s3fs`` for ``s3://``, ``gcsfs`` for ``gs://``) installed. Connection settings come from
fsspec's own configuration, e.g. ``FSSPEC_S3_ENDPOINT_URL=http://127.0.0.1:9000`` and the usual
``AWS_ACCESS_KEY_ID`` / ``AWS_SECRET_ACCESS_KEY`` for an S3-compatible server.

Object stores have no atomic directory rename, so a scene is uploaded file by file with
``_SUCCESS`` last (:func:`upload_dir`); readers trust only directories holding ``_SUCCESS``
(:func:`complete_scenes`).
"""

from __future__ import annotations

import inspect
import os
import pathlib
import re
from collections.abc import Callable

from kubric.errors import KubricError, UsageError

_URL_RE = re.compile(r"^([a-zA-Z][a-zA-Z0-9+.\-]*)://(.*)$")


class StorageError(KubricError, ValueError):
    """A malformed, unreachable or unwritable location (one line, names the location)."""


class StorageUsageError(StorageError, UsageError):
    """A location given that cannot name an output at all (empty, a URL without a bucket):
    a bad option, exit status 2 (docs/exit-codes.md)."""


def is_url(location) -> bool:
    """True for ``scheme://...`` strings (``file://`` included); False for plain paths."""
    return isinstance(location, str) and bool(_URL_RE.match(location))


def normalise(location) -> str:
    """A canonical string form: URLs without a trailing slash, local paths absolute. An empty
    location raises :class:`StorageError` (it would silently mean the current directory)."""
    if not str(location).strip():
        raise StorageUsageError(f"output location {str(location)!r} is empty (give a directory or a "
                           f"URL; '.' for the current directory)")
    if is_url(location):
        scheme, rest = _URL_RE.match(location).groups()
        rest = rest.rstrip("/")
        if not rest:
            raise StorageUsageError(f"output URL {location!r} names no bucket or path")
        return f"{scheme.lower()}://{rest}"
    return str(pathlib.Path(location).expanduser().resolve())


def join(location, *parts: str) -> str:
    """``location/part/...`` for URLs and paths."""
    if is_url(location):
        return "/".join([str(location).rstrip("/"), *(p.strip("/") for p in parts)])
    return str(pathlib.Path(location, *parts))


def _fs(location):
    """(filesystem, path) for ``location``; a local filesystem for plain paths. The filesystem's
    cached listings are dropped first: other processes write the same store."""
    fs, path = _filesystem(location)
    fs.invalidate_cache()
    return _with_deadline(fs), path


class _Deadlined:
    """An async filesystem (s3fs, gcsfs) whose blocking calls each end within
    :func:`operation_deadline` seconds (fsspec raises ``FSTimeoutError``): a request the store
    accepts and never answers (botocore waits for ``100-continue`` without its read timeout)
    cannot hang a command."""

    def __init__(self, fs, seconds: float):
        self._fs, self._seconds = fs, seconds

    def __getattr__(self, name):
        attr = getattr(self._fs, name)
        coroutine = getattr(self._fs, f"_{name}", None)
        if name.startswith("_") or not callable(attr) or \
                not inspect.iscoroutinefunction(coroutine):
            return attr
        from fsspec.asyn import sync

        def call(*args, **kwargs):
            return sync(self._fs.loop, coroutine, *args, timeout=self._seconds, **kwargs)
        return call


def operation_deadline() -> float:
    """Seconds one store operation (a listing, an upload, a copy) may take in all: 10 × the
    read timeout (``KUBRIC_STORE_TIMEOUT``, default :data:`READ_TIMEOUT_S`)."""
    return 10 * _read_timeout()


def _with_deadline(fs):
    from fsspec.asyn import AsyncFileSystem
    return _Deadlined(fs, operation_deadline()) if isinstance(fs, AsyncFileSystem) else fs


def _filesystem(location):
    try:
        import fsspec
    except ModuleNotFoundError as err:  # pragma: no cover - fsspec ships with the cluster extra
        raise StorageError(f"{location!r}: URLs need fsspec (pip install 'kubric[cluster]')") \
            from err
    if not is_url(location):
        return fsspec.filesystem("file"), str(location)
    scheme = _URL_RE.match(location).group(1).lower()
    try:
        if scheme in ("file", "local"):  # as local paths: parent directories made on write
            return fsspec.filesystem("file", auto_mkdir=True), _URL_RE.match(location).group(2)
        fs, path = fsspec.core.url_to_fs(location, **deadlines(scheme))
        if scheme in ("s3", "s3a"):
            fs.retries = ATTEMPTS  # s3fs's own retries (a class attribute, not an argument)
        return fs, path
    except ValueError as err:
        raise StorageError(f"{location!r}: unknown storage protocol {scheme!r} ({err})") from err
    except ImportError as err:
        raise StorageError(f"{location!r}: protocol {scheme!r} needs a package that is not "
                           f"installed ({err})") from err


#: seconds a request to an object store may wait for a connection / for an answer
#: (``KUBRIC_STORE_TIMEOUT`` overrides the second), and the client's attempts per request
CONNECT_TIMEOUT_S = 10.0
READ_TIMEOUT_S = 60.0
ATTEMPTS = 3


def deadlines(scheme: str) -> dict:
    """Keyword arguments giving every request of ``scheme``'s filesystem a deadline (S3: botocore's
    connect / read timeouts, one botocore attempt inside s3fs's own retries, set to
    :data:`ATTEMPTS` by :func:`_filesystem`), so
    a stalled store ends in a one-line error instead of a silent wait. Settings of fsspec's
    configuration (``fsspec.config.conf``) win."""
    if scheme not in ("s3", "s3a"):
        return {}
    import fsspec.config
    read = _read_timeout()
    conf = fsspec.config.conf.get(scheme, {})
    config = {"connect_timeout": min(CONNECT_TIMEOUT_S, read), "read_timeout": read,
              "retries": {"max_attempts": 1, "mode": "standard"},
              **conf.get("config_kwargs", {})}
    return {"config_kwargs": config}


def _read_timeout() -> float:
    try:
        read = float(os.environ.get("KUBRIC_STORE_TIMEOUT", READ_TIMEOUT_S))
    except ValueError:
        raise StorageError(f"KUBRIC_STORE_TIMEOUT={os.environ['KUBRIC_STORE_TIMEOUT']!r} is not "
                           "a number of seconds") from None
    if not 0 < read < float("inf"):
        raise StorageError(f"KUBRIC_STORE_TIMEOUT must be a finite number of seconds > 0, got "
                           f"{read}")
    return read


def failure(err: BaseException) -> str:
    """One line describing a failed store request (a timeout names the deadline)."""
    if type(err).__name__ in ("FSTimeoutError", "TimeoutError", "ReadTimeoutError",
                              "ConnectTimeoutError"):
        return (f"no answer within the deadline ({type(err).__name__}; KUBRIC_STORE_TIMEOUT="
                f"{_read_timeout():g} s per request, {operation_deadline():g} s per operation)")
    text = " ".join(str(err).split())[:200]
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def backend_errors() -> tuple[type[BaseException], ...]:
    """The exception types of a failed, refused or timed-out request to an object store (not a
    missing object, not a local disk error), for callers that turn them into one line."""
    found: list[type[BaseException]] = [ConnectionError, TimeoutError]
    for module, names in (("botocore.exceptions", ("BotoCoreError", "ClientError")),
                          ("aiohttp", ("ClientError",)), ("fsspec.exceptions", ("FSTimeoutError",))):
        try:
            mod = __import__(module, fromlist=list(names))
        except ImportError:
            continue
        found += [getattr(mod, n) for n in names if hasattr(mod, n)]
    return tuple(found)


def exists(location) -> bool:
    if not is_url(location):
        return os.path.exists(location)
    fs, path = _fs(location)
    return fs.exists(path)


def isfile(location) -> bool:
    if not is_url(location):
        return os.path.isfile(location)
    fs, path = _fs(location)
    return fs.isfile(path)


def listdir(location) -> list[str]:
    """Names (not paths) directly under ``location``; empty when it does not exist."""
    if not is_url(location):
        try:
            return sorted(os.listdir(location))
        except (FileNotFoundError, NotADirectoryError):
            return []
    fs, path = _fs(location)
    try:
        entries = fs.ls(path, detail=False)
    except FileNotFoundError:
        return []
    return sorted({e.rstrip("/").rsplit("/", 1)[-1] for e in entries} - {""})


def open_file(location, mode: str = "rb"):
    """A file object for a path or URL (a context manager, as ``open``)."""
    if not is_url(location):
        return open(location, mode)
    fs, path = _fs(location)
    return fs.open(path, mode)


def read_bytes(location) -> bytes:
    if is_url(location):  # one call, under the operation's deadline
        fs, path = _fs(location)
        return fs.cat_file(path)
    with open_file(location, "rb") as fh:
        return fh.read()


def write_bytes(location, data: bytes) -> None:
    """Write a whole file (local: via a temporary sibling and rename)."""
    if not is_url(location):
        target = pathlib.Path(location)
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(f".{target.name}.tmp-{os.getpid()}")
        tmp.write_bytes(data)
        os.replace(tmp, target)
        return
    fs, path = _fs(location)
    fs.pipe_file(path, data)


def remove(location) -> None:
    """Delete a file or a directory tree; nothing when absent."""
    if not is_url(location):
        import shutil
        if os.path.isdir(location):
            shutil.rmtree(location, ignore_errors=True)
        elif os.path.exists(location):
            os.remove(location)
        return
    fs, path = _fs(location)
    try:
        fs.rm(path, recursive=True)
    except FileNotFoundError:
        pass


def upload_file(local_file, location) -> None:
    """Copy one local file to ``location`` (a path: through a temporary sibling and rename)."""
    if not is_url(location):
        write_bytes(location, pathlib.Path(local_file).read_bytes())
        return
    fs, path = _fs(location)
    fs.put_file(str(local_file), path)


def download_file(location, local_file) -> pathlib.Path:
    """Copy the file at ``location`` to ``local_file`` (written to a temporary sibling and
    renamed, so a cut transfer never leaves a file under the final name); returns its path."""
    target = pathlib.Path(local_file)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.part-{os.getpid()}")
    try:
        if is_url(location):
            fs, path = _fs(location)
            fs.get_file(path, str(tmp))
        else:
            import shutil
            shutil.copyfile(location, tmp)
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)
    return target


def copy(source, target) -> None:
    """Copy one file within a store (server-side for object stores: no bytes pass through
    this machine); both must be paths or both URLs of the same filesystem."""
    if not is_url(source):
        write_bytes(target, pathlib.Path(source).read_bytes())
        return
    fs, src = _fs(source)
    _, dst = _filesystem(target)
    fs.copy(src, dst)


def sizes(location) -> dict[str, int]:
    """``{name: size in bytes}`` of the files directly under ``location`` (one listing)."""
    if not is_url(location):
        try:
            return {e.name: e.stat().st_size for e in os.scandir(location) if e.is_file()}
        except (FileNotFoundError, NotADirectoryError):
            return {}
    fs, path = _fs(location)
    try:
        entries = fs.ls(path, detail=True)
    except FileNotFoundError:
        return {}
    return {e["name"].rstrip("/").rsplit("/", 1)[-1]: int(e.get("size") or 0)
            for e in entries if e.get("type") == "file"}


def upload_dir(local_dir, location, last: str = "_SUCCESS",
               on_file: Callable[[str, int, int], None] | None = None) -> list[str]:
    """Copy the files under ``local_dir`` to ``location`` one by one, ``last`` (when present)
    after all others; returns the relative paths in upload order. Whatever ``location`` held
    before is removed first, so a half-finished earlier upload never mixes with this one.
    ``on_file(relative_path, k, n)`` is called after each file."""
    local_dir = pathlib.Path(local_dir)
    files = sorted(p.relative_to(local_dir).as_posix() for p in local_dir.rglob("*") if p.is_file())
    order = [f for f in files if f != last] + ([last] if last in files else [])
    remove(location)
    if not is_url(location):
        import shutil
        for k, rel in enumerate(order, start=1):
            target = pathlib.Path(location, rel)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(local_dir / rel, target)
            on_file and on_file(rel, k, len(order))
        return order
    fs, path = _fs(location)
    for k, rel in enumerate(order, start=1):
        fs.put_file(str(local_dir / rel), f"{path.rstrip('/')}/{rel}")
        on_file and on_file(rel, k, len(order))
    return order


def download_dir(location, local_dir) -> pathlib.Path:
    """Copy the files under ``location`` into ``local_dir`` (created); returns it."""
    local_dir = pathlib.Path(local_dir)
    local_dir.mkdir(parents=True, exist_ok=True)
    fs, path = _fs(location)
    root = path.rstrip("/")
    for remote in fs.find(root):
        rel = remote[len(root):].lstrip("/")
        if not rel:
            continue
        target = local_dir / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        fs.get_file(remote, str(target))
    return local_dir


def complete_scenes(root, success: str = "_SUCCESS") -> list[str]:  # scene_dir.SUCCESS_FILE
    """Names of the ``scene_*`` directories under ``root`` that hold ``success`` — the only ones
    a reader (pack, inspect, resume) may treat as data."""
    names = [n for n in listdir(root) if n.startswith("scene_")]  # kubric.io.scene_dir naming
    if not is_url(root):
        return [n for n in names if os.path.isfile(os.path.join(root, n, success))]
    fs, path = _fs(root)
    markers = [f"{path.rstrip('/')}/{n}/{success}" for n in names]
    return [n for n, ok in zip(names, _exist_many(fs, markers), strict=True) if ok]


def _exist_many(fs, paths: list[str], concurrency: int = 64) -> list[bool]:
    """``fs.exists`` of every path; on an async filesystem (s3fs, gcsfs) ``concurrency`` requests
    at a time. One request per path, whatever else the prefixes hold: a glob of
    ``scene_*/_SUCCESS`` walked every scene prefix one listing after the other (measured on
    moto's S3, 1000 scenes: 9.0 s; see benchmarks/bench_scale.py)."""
    from fsspec.asyn import AsyncFileSystem, sync
    inner = fs._fs if isinstance(fs, _Deadlined) else fs
    if not isinstance(inner, AsyncFileSystem) or not paths:
        return [fs.exists(p) for p in paths]
    import asyncio

    async def check():
        gate = asyncio.Semaphore(concurrency)

        async def one(p):
            async with gate:
                return await inner._exists(p)
        return await asyncio.gather(*(one(p) for p in paths))
    return list(sync(inner.loop, check, timeout=operation_deadline()))


WRITE_PROBE_PREFIX = ".kubric-write-test-"
"""Names :func:`check_writable` gives its short-lived probe files (another process checking the
same output at the same moment may see one: it is not foreign content)."""


def check_writable(location) -> None:
    """Raise :class:`StorageError` (one line) unless files can be written under ``location``;
    leaves nothing behind (a URL gets a probe file, deleted again)."""
    probe_name = f"{WRITE_PROBE_PREFIX}{os.getpid()}"
    if not is_url(location):  # checked without creating anything
        path = pathlib.Path(location).expanduser().absolute()
        existing = next(p for p in (path, *path.parents) if p.exists())
        if not existing.is_dir():
            raise StorageError(f"output {str(location)!r}: {str(existing)!r} is a file, not a "
                               f"directory")
        if not os.access(existing, os.W_OK | os.X_OK):
            raise StorageError(f"output {str(location)!r} is not writable: no write permission "
                               f"on {str(existing)!r}")
        return
    probe = join(location, probe_name)
    try:
        write_bytes(probe, b"")
        remove(probe)
    except StorageError:
        raise
    except Exception as err:  # each backend raises its own types (botocore, aiohttp, OSError)
        raise StorageError(f"output {location!r} is not writable: {failure(err)}") from err


__all__ = ["WRITE_PROBE_PREFIX", "StorageError",
           "backend_errors", "check_writable", "complete_scenes", "copy",
           "deadlines", "download_dir", "download_file", "exists", "failure", "is_url", "isfile",
           "join", "listdir", "normalise", "open_file", "operation_deadline", "read_bytes",
           "remove", "sizes", "upload_dir", "upload_file", "write_bytes"]
