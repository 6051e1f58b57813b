"""What the Hub exports share: the input (a packed dataset, or scene folders packed first into
the work folder), the loader's examples one scene at a time (memory flat in the number of
scenes), the progress bar, and the output written into a work folder renamed into place only
when complete (nothing that looks complete after a failure, as ``kubric pack``)."""

from __future__ import annotations

import contextlib
import importlib
import os
import pathlib
import shutil
import sys
from collections.abc import Iterator

from kubric.datasets import layout, load
from kubric.datasets.exports.scenes import ExportError
from kubric.io import scene_dir
from kubric.io.output_check import OutputError

#: the folder, inside the work folder, where scene folders are packed before an export
PACKED = ".packed"


def need(module: str):
    """``module`` imported, or one line naming the extra that installs it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise ExportError(f"this export needs the Python package {module!r}: install the hub "
                          "extra (pip install 'kubric[hub]')") from None


def check_out(out) -> pathlib.Path:
    """``out`` as a path: it must not exist, or be an empty directory."""
    out = pathlib.Path(out)
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise OutputError(f"--out {str(out)!r} exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        raise OutputError(f"--out {str(out)!r} is not empty (an export writes a new folder)")
    return out


def work_dir(out: pathlib.Path) -> pathlib.Path:
    """The work folder of an export into ``out``: ``.NAME.incomplete`` beside it."""
    return out.parent / f".{out.name}.incomplete"


@contextlib.contextmanager
def writing(out) -> Iterator[pathlib.Path]:
    """Yield a fresh work folder; rename it to ``out`` when the block ends normally, remove it
    when it raises (an interrupted export leaves nothing named ``out``)."""
    out = check_out(out)
    work = work_dir(out)
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    try:
        yield work
        shutil.rmtree(work / PACKED, ignore_errors=True)
        if out.is_dir():
            out.rmdir()  # empty (checked)
        os.replace(work, out)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise


def dataset_of(source, work: pathlib.Path, splits: str, progress: bool
               ) -> tuple[pathlib.Path, pathlib.Path | None]:
    """(packed dataset directory, scene folder or None) for ``source``: a packed dataset is used
    as it is; a folder of scene directories is packed into ``work/.packed`` with ``splits``."""
    path = pathlib.Path(source)
    if layout.is_dataset(path):
        return path, None
    if not path.is_dir():
        raise ExportError(f"{str(source)!r} is not a directory (expected a packed dataset or a "
                          "folder of scene directories)")
    complete, _ = scene_dir.survey(path)
    if not complete and not scene_dir.is_complete(path):
        raise ExportError(f"{str(source)!r} is neither a packed dataset ({layout.INFO_FILE}) nor "
                          f"a folder of complete scene directories")
    from kubric.datasets import pack
    pack(path, work / PACKED, splits=splits, progress=progress)
    return work / PACKED, path


def splits_of(dataset_dir: pathlib.Path) -> dict[str, int]:
    """{split: number of scenes} of a packed dataset, the empty splits left out."""
    return {s: int(n) for s, n in layout.read_info(dataset_dir)["counts"].items() if n}


def scene_examples(dataset_dir, split: str) -> Iterator[dict]:
    """The loader's examples of ``split``, one at a time."""
    source = load(dataset_dir, split)
    for index in range(len(source)):
        yield source[index]


def progress_bar(total: int, what: str, enabled: bool):
    from tqdm import tqdm
    return tqdm(total=total, unit="scene", desc=f"export {what}", file=sys.stderr,
                disable=not enabled)
