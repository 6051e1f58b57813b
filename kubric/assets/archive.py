"""Asset archives: deterministic ``.tar.gz`` writing and **safe** extraction.

Writing: members in sorted order, mtime 0, uid/gid 0, no user/group names, mode 0o644, and a gzip
header with mtime 0 and no file name — the same files always give byte-identical archives.

Extraction refuses (with :class:`UnsafeArchiveError`, naming the asset and the member): absolute
paths, members whose path leaves the target directory (``..``), symbolic and hard links, device
files and FIFOs, members larger than ``max_member_bytes`` and archives whose members add up to more
than ``max_total_bytes``. A truncated or corrupt archive raises :class:`CorruptArchiveError` naming
the asset. Extraction goes to a temporary sibling directory that is renamed into place only once
complete, so a failed extraction never leaves a half-written asset directory behind.
"""

from __future__ import annotations

import errno
import gzip
import io
import os
import shutil
import tarfile
import tempfile
import zlib
from pathlib import Path, PurePosixPath

from kubric.errors import KubricError

#: default limits of :func:`safe_extract` (bytes).
MAX_MEMBER_BYTES = 512 * 1024**2
MAX_TOTAL_BYTES = 2 * 1024**3


#: errors of the destination (full disk, quota, read-only, no permission), not of the archive
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM})


class AssetArchiveError(KubricError, RuntimeError):
    """Base of the archive errors."""


class UnsafeArchiveError(AssetArchiveError):
    """An archive member that could write outside the target or is not a plain file/folder."""


class CorruptArchiveError(AssetArchiveError):
    """A missing, truncated or otherwise unreadable archive."""


def write_archive(src_dir: str | os.PathLike, archive_path: str | os.PathLike) -> Path:
    """Pack every regular file under ``src_dir`` into a deterministic ``.tar.gz``.

    Paths inside the archive are relative to ``src_dir`` (POSIX separators). The archive is
    written to a temporary file and renamed, so readers never see a partial archive.
    """
    src = Path(src_dir)
    out = Path(archive_path)
    files = sorted(p for p in src.rglob("*") if p.is_file() and not p.is_symlink())
    raw = io.BytesIO()
    with tarfile.open(fileobj=raw, mode="w", format=tarfile.PAX_FORMAT) as tar:
        for path in files:
            info = tarfile.TarInfo(path.relative_to(src).as_posix())
            data = path.read_bytes()
            info.size = len(data)
            info.mtime = 0
            info.mode = 0o644
            info.uid = info.gid = 0
            info.uname = info.gname = ""
            tar.addfile(info, io.BytesIO(data))
    tmp = out.with_name(out.name + ".tmp")
    with open(tmp, "wb") as fh, gzip.GzipFile(filename="", mode="wb", fileobj=fh,
                                              compresslevel=6, mtime=0) as gz:
        gz.write(raw.getvalue())
    os.replace(tmp, out)
    return out


def _check_member(member: tarfile.TarInfo, asset_id: str, max_member_bytes: int) -> PurePosixPath:
    name = member.name
    where = f"asset {asset_id!r}: archive member {name!r}"
    if name.startswith(("/", "\\")) or (len(name) > 1 and name[1] == ":"):
        raise UnsafeArchiveError(f"{where} has an absolute path; only relative paths are allowed")
    rel = PurePosixPath(name.replace("\\", "/"))
    if any(part == ".." for part in rel.parts):
        raise UnsafeArchiveError(f"{where} leaves the extraction directory ('..' in its path)")
    if member.issym() or member.islnk():
        raise UnsafeArchiveError(f"{where} is a link (to {member.linkname!r}); links are refused")
    if not (member.isfile() or member.isdir()):
        raise UnsafeArchiveError(f"{where} is a device, FIFO or other special file; only regular "
                                 "files and folders are allowed")
    if member.size > max_member_bytes:
        raise UnsafeArchiveError(f"{where} is {member.size} bytes, more than the limit of "
                                 f"{max_member_bytes} bytes")
    return rel


def build_staged(target: Path, fill, complete=Path.is_dir) -> Path:
    """Run ``fill(staging)`` in a temporary sibling of ``target``, then rename it into place (if
    another process finished first — ``complete(target)`` is true — its copy is kept); nothing
    is left behind on failure."""
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    try:
        fill(staging)
        try:
            os.rename(staging, target)
        except OSError:
            if not complete(target):
                raise
            shutil.rmtree(staging)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return target


def _write_checked(checked, staging: Path, asset_id: str, archive_path: Path, open_member,
                   max_total_bytes: int) -> None:
    """Write checked members ``(info, name, rel, is_dir, size)`` under ``staging``;
    ``open_member(info)`` returns a readable file object."""
    import zipfile

    total = sum(size for *_, size in checked)
    if total > max_total_bytes:
        raise UnsafeArchiveError(f"asset {asset_id!r}: archive members add up to {total} "
                                 f"bytes, more than the limit of {max_total_bytes}")
    root = staging.resolve()
    for info, name, rel, is_dir, _ in checked:
        dest = (staging / rel).resolve()
        if dest != root and root not in dest.parents:
            raise UnsafeArchiveError(f"asset {asset_id!r}: archive member {name!r} "
                                     "resolves outside the extraction directory")
        if is_dir:
            dest.mkdir(parents=True, exist_ok=True)
            continue
        dest.parent.mkdir(parents=True, exist_ok=True)
        try:
            with open_member(info) as src, open(dest, "wb") as fh:
                shutil.copyfileobj(src, fh)
        except OSError as err:
            if err.errno in WRITE_ERRNOS:  # the disk, not the archive: say so, naming the place
                raise OSError(err.errno, f"{err.strerror} (extracting member {name!r} of asset "
                              f"{asset_id!r})", str(dest)) from None
            raise CorruptArchiveError(f"asset {asset_id!r}: archive {str(archive_path)!r} is "
                                      f"corrupt or truncated (member {name!r}): {err}") from None
        except (tarfile.TarError, zipfile.BadZipFile, EOFError, zlib.error) as err:
            raise CorruptArchiveError(f"asset {asset_id!r}: archive {str(archive_path)!r} is "
                                      f"corrupt or truncated (member {name!r}): {err}") from None


def safe_extract(archive_path: str | os.PathLike, target_dir: str | os.PathLike, asset_id: str,
                 max_member_bytes: int = MAX_MEMBER_BYTES,
                 max_total_bytes: int = MAX_TOTAL_BYTES) -> Path:
    """Extract ``archive_path`` into ``target_dir`` (created; must not exist yet) safely.

    Every member is checked before anything is written; see the module docstring for what is
    refused. Returns the target directory.
    """
    archive_path = Path(archive_path)
    if not archive_path.is_file():
        raise CorruptArchiveError(f"asset {asset_id!r}: archive {str(archive_path)!r} is missing")
    try:
        tar = tarfile.open(archive_path, mode="r:*")
    except (tarfile.TarError, OSError, EOFError, zlib.error) as err:
        raise CorruptArchiveError(f"asset {asset_id!r}: cannot read archive "
                                  f"{str(archive_path)!r}: {err}") from None

    def fill(staging: Path) -> None:
        with tar:
            try:
                members = tar.getmembers()
            except (tarfile.TarError, OSError, EOFError, zlib.error) as err:
                raise CorruptArchiveError(f"asset {asset_id!r}: archive {str(archive_path)!r} is "
                                          f"corrupt or truncated: {err}") from None
            checked = [(m, m.name, _check_member(m, asset_id, max_member_bytes), m.isdir(),
                        m.size) for m in members]
            _write_checked(checked, staging, asset_id, archive_path, tar.extractfile,
                           max_total_bytes)

    return build_staged(Path(target_dir), fill)


def safe_extract_zip(zip_path: str | os.PathLike, target_dir: str | os.PathLike, asset_id: str,
                     max_member_bytes: int = MAX_MEMBER_BYTES,
                     max_total_bytes: int = MAX_TOTAL_BYTES) -> Path:
    """Extract a ``.zip`` (e.g. one Google Scanned Objects model) with the checks of
    :func:`safe_extract`: absolute paths, ``..``, symbolic links and special files (the Unix mode
    in a member's external attributes), absurd sizes and corrupt archives are refused before
    anything is written; the target appears only when complete."""
    import stat
    import zipfile

    zip_path = Path(zip_path)
    if not zip_path.is_file():
        raise CorruptArchiveError(f"asset {asset_id!r}: archive {str(zip_path)!r} is missing")
    try:
        zf = zipfile.ZipFile(zip_path)
    except (zipfile.BadZipFile, OSError) as err:
        raise CorruptArchiveError(f"asset {asset_id!r}: cannot read zip {str(zip_path)!r}: "
                                  f"{err}") from None

    def fill(staging: Path) -> None:
        with zf:
            checked = []
            for info in zf.infolist():
                as_tar = tarfile.TarInfo(info.filename)
                ftype = stat.S_IFMT(info.external_attr >> 16)  # 0: no Unix mode recorded
                if ftype == stat.S_IFLNK:
                    as_tar.type = tarfile.SYMTYPE
                elif ftype not in (0, stat.S_IFREG, stat.S_IFDIR):
                    as_tar.type = tarfile.FIFOTYPE
                elif info.is_dir():
                    as_tar.type = tarfile.DIRTYPE
                as_tar.size = info.file_size
                rel = _check_member(as_tar, asset_id, max_member_bytes)
                checked.append((info, info.filename, rel, info.is_dir(), info.file_size))
            _write_checked(checked, staging, asset_id, zip_path, zf.open, max_total_bytes)

    return build_staged(Path(target_dir), fill)
