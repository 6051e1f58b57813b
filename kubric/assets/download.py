"""HTTP downloads for the collection builders: JSON requests and resumable, verified files.

Only the standard library is used (``urllib``). A file is downloaded into ``<dest>.part``; an
interrupted transfer leaves the ``.part`` file behind and the next attempt (in the same call, up
to ``retries`` times, or in a later run) asks the server for the rest with an HTTP ``Range``
header. A server that ignores the range (status 200) restarts the file from the beginning. The
finished file is checked against the expected size and MD5 (when given) before it is renamed to
``dest``; a mismatch deletes the partial data and raises :class:`DownloadError`, so a corrupt file
never sits where a good one is expected. The whole call, retries included, has the overall
deadline ``$KUBRIC_FETCH_DEADLINE`` (seconds, default 3600), checked as bytes arrive: a server
that trickles bytes fails instead of hanging (the per-read timeout restarts with every byte).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import urllib.error
import urllib.request
from pathlib import Path

from kubric.assets.remote_source import deadline_s
from kubric.errors import KubricError

USER_AGENT = "kubric-assets/1.0 (+https://github.com/google-research/kubric)"
CHUNK = 1 << 16
TIMEOUT_S = 60


class DownloadError(KubricError, RuntimeError):
    """A download that failed, was cut too often, or does not match its size / checksum."""


def _request(url: str, headers: dict | None = None):
    req = urllib.request.Request(url, headers={"User-Agent": USER_AGENT, **(headers or {})})
    return urllib.request.urlopen(req, timeout=TIMEOUT_S)  # noqa: S310 - http(s) URLs only


def _check_scheme(url: str) -> None:
    if not url.startswith(("http://", "https://")):
        raise DownloadError(f"only http(s) URLs can be downloaded, got {url!r}")


def get_json(url: str, missing_ok: bool = False):
    """GET ``url`` and parse its JSON body. With ``missing_ok`` a 404 or an empty body gives None."""
    _check_scheme(url)
    try:
        with _request(url) as resp:
            body = resp.read()
    except urllib.error.HTTPError as err:
        if missing_ok and err.code == 404:
            return None
        raise DownloadError(f"GET {url}: HTTP {err.code} {err.reason}") from None
    except (urllib.error.URLError, OSError) as err:
        raise DownloadError(f"GET {url}: {err}") from None
    if not body.strip():
        if missing_ok:
            return None
        raise DownloadError(f"GET {url}: empty answer, expected JSON")
    try:
        return json.loads(body)
    except json.JSONDecodeError as err:
        raise DownloadError(f"GET {url}: the answer is not JSON ({err})") from None


def file_digest(path: str | os.PathLike, algorithm: str) -> str:
    """Hex digest of a file's bytes (``algorithm``: a hashlib name, e.g. ``"sha256"``)."""
    digest = hashlib.new(algorithm)
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def md5_of(path: str | os.PathLike) -> str:
    return file_digest(path, "md5")  # the checksum Poly Haven publishes


def sha256_of(path: str | os.PathLike) -> str:
    return file_digest(path, "sha256")


def _verify(path: Path, url: str, size: int | None, md5: str | None,
            sha256: str | None = None, check=None) -> None:
    got = path.stat().st_size
    if size is not None and got != int(size):
        raise DownloadError(f"{url}: got {got} bytes, the listing says {int(size)}")
    if md5 is not None:
        got_md5 = md5_of(path)
        if got_md5.lower() != str(md5).lower():
            raise DownloadError(f"{url}: MD5 {got_md5} does not match the listing's {md5}")
    if sha256 is not None:
        got_sha = sha256_of(path)
        if got_sha.lower() != str(sha256).lower():
            raise DownloadError(f"{url}: SHA-256 {got_sha} does not match the server's {sha256}")
    if check is not None:
        try:
            check(path)
        except (OSError, ValueError, EOFError) as err:
            raise DownloadError(f"{url}: the downloaded file is not whole ({err})") from None


def _transfer(url: str, part: Path, size: int | None, deadline: float = float("inf")) -> None:
    """One attempt: append the missing bytes to ``part`` (or start over); raises on a cut."""
    have = part.stat().st_size if part.is_file() else 0
    if size is not None and have > int(size):
        part.unlink()
        have = 0
    if size is not None and have == int(size):
        return
    headers = {"Range": f"bytes={have}-"} if have else {}
    try:
        resp = _request(url, headers)
    except urllib.error.HTTPError as err:
        if err.code == 416 and have:  # nothing left to send: the part file is complete
            return
        raise DownloadError(f"GET {url}: HTTP {err.code} {err.reason}") from None
    with resp:
        mode = "ab" if have and resp.status == 206 else "wb"
        announced = resp.headers.get("Content-Length")
        got = 0
        with open(part, mode) as fh:
            while True:
                block = resp.read1(CHUNK)  # one receive: the deadline is checked per arrival
                if not block:
                    break
                fh.write(block)
                got += len(block)
                if time.monotonic() > deadline:
                    raise DownloadError(f"GET {url}: not complete within $KUBRIC_FETCH_DEADLINE "
                                        f"({got} bytes this attempt); the partial file "
                                        f"{str(part)!r} is kept for the next run")
        if announced is not None and got < int(announced):
            raise ConnectionError(f"connection closed after {got} of {int(announced)} bytes")


def fetch_file(url: str, dest: str | os.PathLike, size: int | None = None,
               md5: str | None = None, retries: int = 3, sha256: str | None = None,
               check=None) -> Path:
    """Download ``url`` to ``dest`` (resuming a ``.part`` file), verify size / MD5 / SHA-256 and
    ``check(path)`` (a content check raising ``ValueError``, ``OSError`` or ``EOFError``), rename.

    An existing ``dest`` that matches ``size`` / ``md5`` / ``sha256`` is kept without any
    request. Returns
    ``dest``. Raises :class:`DownloadError` naming the URL when the server fails, the transfer is
    cut more than ``retries`` times in a row, or the result does not match.
    """
    import http.client

    _check_scheme(url)
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    if dest.is_file():
        try:
            _verify(dest, url, size, md5, sha256)
            return dest
        except DownloadError:
            dest.unlink()
    part = dest.with_name(dest.name + ".part")
    deadline = time.monotonic() + deadline_s()
    for attempt in range(retries + 1):
        try:
            _transfer(url, part, size, deadline)
            break
        except (http.client.IncompleteRead, ConnectionError, TimeoutError,
                urllib.error.URLError, OSError) as err:
            if attempt == retries or time.monotonic() > deadline:
                raise DownloadError(f"GET {url}: cut {attempt + 1} times, last: {err}; the "
                                    f"partial file {str(part)!r} is kept for the next run") from None
            time.sleep(min(2.0 ** attempt * 0.1, 5.0))
    try:
        _verify(part, url, size, md5, sha256, check)
    except DownloadError:
        part.unlink(missing_ok=True)
        raise
    os.replace(part, dest)
    return dest
