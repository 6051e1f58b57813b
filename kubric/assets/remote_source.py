"""Asset sources at URLs: ``http(s)://``, ``s3://``, ``gs://`` or any fsspec URL.

``AssetSource("https://host/kubasic")`` (or ``.../kubasic/manifest.json``, ``s3://bucket/kubasic``,
...) downloads the manifest once per machine into ``KUBRIC_CACHE_DIR/remote/<name>-<hash of the
URL>/`` and each asset's archive the first time that asset is used; later opens of the same URL
(any process on the machine) read the cache and make no request. A source at a URL is treated as
immutable: publish a changed source under a new URL (e.g. with its version in the path), or delete
its cache folder.

* ``http(s)://`` uses the standard library (``urllib``) with a timeout per request
  (``$KUBRIC_FETCH_TIMEOUT`` seconds, default 30) and an overall deadline per file, retries
  included (``$KUBRIC_FETCH_DEADLINE`` seconds, default 3600): a server that trickles bytes
  fails at the deadline instead of hanging. Other schemes go through fsspec (connection
  settings are fsspec's, e.g. ``FSSPEC_S3_ENDPOINT_URL``; timeouts are the backend's).
* Every file is written to a temporary name and renamed when complete and checked: a transfer cut
  short (fewer bytes than announced), a checksum mismatch or a crash leaves nothing that looks like
  a cached file. Concurrent processes on one machine take an exclusive ``flock`` per file, so a
  file is downloaded once and nobody reads a partial one.
* Checksums: a manifest entry may hold ``"sha256"`` and/or ``"md5"`` (hex digests of its archive);
  they are verified after the download (and, for local sources too, before extraction). The
  builders record ``sha256`` of every archive they write. Every archive is also read through
  whole before it is cached (:func:`kubric.assets.archive.check_complete`), so a transfer cut
  short without a ``Content-Length`` (or with an understated one), or a file that is no archive,
  is never cached, with or without checksums.
* ``data_dir`` in a remote manifest is relative to the manifest's URL (or an absolute URL).
  Archives are extracted from the cache with the same checks as local ones
  (:func:`kubric.assets.archive.safe_extract`), and cached under a name derived from their URL, so
  an entry's ``path`` cannot place a file outside the cache.
* ``file://`` URLs are local paths and are read in place.

Errors are one line (:class:`RemoteSourceError`) naming the URL: unreachable host, no answer
within the timeout, HTTP status (404, ...), a cut transfer, a checksum mismatch; a malformed
manifest is a :class:`~kubric.assets.asset_source.ManifestError`.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import time
from pathlib import Path

from kubric.assets.archive import check_complete
from kubric.assets.manifest import ManifestError, cache_dir, validate_manifest
from kubric.errors import KubricError
from kubric.io import storage

TIMEOUT_ENV = "KUBRIC_FETCH_TIMEOUT"
DEFAULT_TIMEOUT_S = 30.0
DEADLINE_ENV = "KUBRIC_FETCH_DEADLINE"
DEFAULT_DEADLINE_S = 3600.0
CHECKSUMS = ("sha256", "md5")
CHUNK = 1 << 20
RETRIES = 2  # extra attempts after a transfer cut short
USER_AGENT = "kubric-asset-source/1.0"


class RemoteSourceError(KubricError, RuntimeError):
    """An asset-source URL that cannot be fetched, or a file that fails its checks (one line)."""


def is_remote(location) -> bool:
    """True for URLs that are downloaded (every scheme but ``file://``)."""
    return storage.is_url(location) and not str(location).lower().startswith("file://")


def local_path(location):
    """``location`` itself, or the path of a ``file://`` URL."""
    if isinstance(location, str) and location.lower().startswith("file://"):
        return location[len("file://"):]
    return location


def manifest_url(url: str) -> str:
    """The manifest's URL for a source folder URL or the manifest URL itself."""
    url = storage.normalise(url)
    return url if url.rsplit("/", 1)[-1].endswith(".json") else f"{url}/manifest.json"


def timeout_s(env: str = TIMEOUT_ENV, default: float = DEFAULT_TIMEOUT_S) -> float:
    """The per-request timeout: ``$KUBRIC_FETCH_TIMEOUT`` seconds, default 30 (or another
    variable's seconds: :func:`deadline_s`)."""
    raw = os.environ.get(env, "").strip()
    if not raw:
        return default
    try:
        value = float(raw)
    except ValueError:
        value = -1.0
    if not 0 < value < float("inf"):
        raise RemoteSourceError(f"{env}={raw!r}: expected a number of seconds > 0")
    return value


def deadline_s() -> float:
    """The overall time allowed for one file: ``$KUBRIC_FETCH_DEADLINE`` seconds, default 3600."""
    return timeout_s(DEADLINE_ENV, DEFAULT_DEADLINE_S)


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]", "_", text)[:60]


def cache_folder(url: str) -> Path:
    """The cache folder of the source whose manifest is at ``url``."""
    murl = manifest_url(url)
    folder = murl.rsplit("/", 2)[-2] if murl.count("/") > 2 else "source"
    digest = hashlib.sha256(murl.encode()).hexdigest()[:16]
    return cache_dir() / "remote" / f"{_safe(folder)}-{digest}"


# ------------------------------------------------------------------------ checksums
def _digest(path: Path, algorithm: str) -> str:
    h = hashlib.new(algorithm)
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(CHUNK), b""):
            h.update(block)
    return h.hexdigest()


def verify_checksums(path, entry: dict, what: str) -> None:
    """Check ``path`` against the entry's ``sha256`` / ``md5`` (those present); raise
    :class:`RemoteSourceError` naming ``what`` on a mismatch."""
    for algorithm in CHECKSUMS:
        expected = entry.get(algorithm)
        if expected is None:
            continue
        got = _digest(Path(path), algorithm)
        if got.lower() != str(expected).lower():
            raise RemoteSourceError(f"{what}: {algorithm} {got} does not match the manifest's "
                                    f"{expected}")


# ------------------------------------------------------------------------ transfers
def _copy_http(url: str, fh, timeout: float, deadline: float) -> None:
    import http.client
    import socket
    import urllib.error
    import urllib.request

    request = urllib.request.Request(url, headers={"User-Agent": USER_AGENT})
    timeout = min(timeout, max(0.01, deadline - time.monotonic()))
    try:
        resp = urllib.request.urlopen(request, timeout=timeout)  # noqa: S310 - http(s) only
    except urllib.error.HTTPError as err:
        raise RemoteSourceError(f"HTTP {err.code} {err.reason}") from None
    except urllib.error.URLError as err:
        reason = err.reason
        if isinstance(reason, (TimeoutError, socket.timeout)):
            raise RemoteSourceError(f"no answer within {timeout:g} s "
                                    f"(${TIMEOUT_ENV})") from None
        raise RemoteSourceError(f"cannot connect ({reason})") from None
    except TimeoutError:
        raise RemoteSourceError(f"no answer within {timeout:g} s "
                                f"(${TIMEOUT_ENV})") from None
    with resp:
        announced = resp.headers.get("Content-Length")
        got = 0
        try:
            # read1: at most one receive per call, so the deadline is checked as bytes trickle in
            # (read(n) loops until n bytes arrive, each receive restarting the socket timeout)
            while block := resp.read1(CHUNK):
                fh.write(block)
                got += len(block)
                if time.monotonic() > deadline:
                    raise _Deadline(f"not complete within ${DEADLINE_ENV} = "
                                    f"{deadline_s():g} s ({got} bytes so far)")
        except http.client.IncompleteRead as err:
            got += len(err.partial)
            raise ConnectionError(f"connection closed after {got} of {announced} bytes") from None
        except TimeoutError:
            raise ConnectionError(f"no data for {timeout:g} s after {got} bytes") from None
        if announced is not None and got != int(announced):
            raise ConnectionError(f"connection closed after {got} of {int(announced)} bytes")


class _Deadline(RemoteSourceError):
    """The file's overall deadline passed (not retried)."""


def _copy_fsspec(url: str, fh) -> None:
    try:
        src = storage.open_file(url, "rb")
    except storage.StorageError as err:
        raise RemoteSourceError(str(err).split(": ", 1)[-1]) from None
    except FileNotFoundError:
        raise RemoteSourceError("not found") from None
    except Exception as err:  # each backend raises its own types (botocore, aiohttp, OSError)
        raise RemoteSourceError(f"cannot open: {_one_line(err)}") from None
    with src:
        size, got = getattr(src, "size", None), 0
        try:
            while block := src.read(CHUNK):
                fh.write(block)
                got += len(block)
        except Exception as err:
            raise ConnectionError(f"reading failed after {got} bytes: {_one_line(err)}") from None
        if size is not None and got != int(size):
            raise ConnectionError(f"got {got} of {int(size)} bytes")


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split())
    return text[:300] if text else type(err).__name__


@contextlib.contextmanager
def _exclusive(lock_path: Path):
    import fcntl
    fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def download(url: str, dest, checksums: dict | None = None, what: str | None = None,
             check=None) -> Path:
    """``dest`` holding the bytes of ``url``, downloaded unless already there (see module doc).

    ``checksums`` (``{"sha256": hex, "md5": hex}``, any subset) and ``check(path)`` (raises on a
    bad file) are applied before the rename; ``what`` names the file in errors (default: the
    URL). Returns ``dest``.
    """
    dest = Path(dest)
    if dest.is_file():
        return dest
    what = what or url
    dest.parent.mkdir(parents=True, exist_ok=True)
    with _exclusive(dest.with_name(f".{dest.name}.lock")):
        if dest.is_file():  # another process finished it while we waited
            return dest
        for stale in dest.parent.glob(f".{dest.name}.*.part"):  # a crashed download's leftovers
            stale.unlink(missing_ok=True)
        tmp = dest.with_name(f".{dest.name}.{os.getpid()}.part")
        timeout = timeout_s()
        deadline = time.monotonic() + deadline_s()
        try:
            for attempt in range(RETRIES + 1):
                try:
                    with open(tmp, "wb") as fh:
                        if url.lower().startswith(("http://", "https://")):
                            _copy_http(url, fh, timeout, deadline)
                        else:
                            _copy_fsspec(url, fh)
                    break
                except RemoteSourceError as err:
                    raise RemoteSourceError(f"{what}: {err}") from None
                except ConnectionError as err:
                    if attempt == RETRIES or time.monotonic() > deadline:
                        raise RemoteSourceError(f"{what}: transfer cut {attempt + 1} times "
                                                f"(last: {err})") from None
                    time.sleep(0.2 * 2 ** attempt)
            verify_checksums(tmp, checksums or {}, what)
            if check is not None:
                check(tmp)
            os.replace(tmp, dest)
        finally:
            tmp.unlink(missing_ok=True)
    return dest


# ------------------------------------------------------------------------ a remote source
def join_url(base: str, rel: str, what: str) -> str:
    """``rel`` (a URL, or a path with ``.`` / ``..`` parts) resolved against the folder URL
    ``base``; a path that climbs above the host or bucket raises :class:`RemoteSourceError`."""
    if storage.is_url(rel):
        return storage.normalise(rel)
    scheme, rest = base.split("://", 1)
    root, _, path = rest.partition("/")
    parts = [p for p in path.split("/") if p]
    for part in rel.split("/"):
        if part == "..":
            if not parts:
                raise RemoteSourceError(f"{what} {rel!r} climbs above {scheme}://{root}/")
            parts.pop()
        elif part not in ("", "."):
            parts.append(part)
    return "/".join([f"{scheme}://{root}", *parts])


class RemoteSource:
    """The cached manifest of the source at ``url`` and its archives (downloaded on demand)."""

    def __init__(self, url: str):
        self.url = manifest_url(url)
        self.folder = cache_folder(self.url)
        self.manifest_path = download(self.url, self.folder / "manifest.json",
                                      what=f"asset source {self.url}",
                                      check=self._check_manifest)

    def _check_manifest(self, path: Path) -> None:
        """A manifest that is not valid JSON or off the format is never cached."""
        try:
            manifest = json.loads(path.read_bytes())
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise ManifestError(f"{self.url}: not valid JSON: {err}") from None
        validate_manifest(manifest, self.url)

    def data_url(self, manifest: dict) -> str:
        """Where the archives are: the manifest's folder URL, or its ``data_dir`` resolved."""
        base = self.url.rsplit("/", 1)[0]
        data_dir = manifest.get("data_dir")
        if not data_dir:
            return base
        return join_url(base, str(data_dir), f"{self.url}: data_dir")

    def archive(self, manifest: dict, asset_id: str, entry: dict) -> Path:
        """The local copy of the asset's archive (downloaded and checked the first time)."""
        rel = entry.get("path", f"{asset_id}.tar.gz")
        url = join_url(self.data_url(manifest), rel, f"asset {asset_id!r}: path")
        digest = hashlib.sha256(url.encode()).hexdigest()[:12]
        name = f"{digest}-{_safe(url.rsplit('/', 1)[-1])}"
        what = f"asset {asset_id!r} ({url})"
        return download(url, self.folder / "archives" / name,
                        {k: entry[k] for k in CHECKSUMS if k in entry}, what=what,
                        check=lambda path: check_complete(path, what))


__all__ = ["RemoteSource", "RemoteSourceError", "download", "is_remote", "join_url", "local_path",
           "manifest_url", "verify_checksums", "cache_folder", "timeout_s"]
