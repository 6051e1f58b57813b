"""The work folder of a pack and its shards (:func:`kubric.datasets.packer.pack`'s writing half).

* ``.NAME.incomplete`` beside the output (:func:`work_dir`) holds the shards being written and
  ``progress.json`` (:data:`PROGRESS_FILE`), the record of every finished shard: its file, its
  scenes, the corrupt scenes it skipped and its size; a record made for another plan, or naming
  a file the folder lacks, is not trusted and the folder starts afresh (:func:`open_work`).
* A shard is written under a temporary name (``NAME-SPLIT.part-NNNNN``) by :class:`ShardWriter`;
  a failed write names the shard, the reason and the free space. :func:`finish_shard` closes it
  and records it.
* :func:`finalise` gives the shards their final TFDS names and writes the TFDS metadata and the
  kubric marker; :func:`swap_into_place` then renames the folder to the output.
"""

from __future__ import annotations

import contextlib
import os
import pathlib
import shutil

from kubric import faults
from kubric.datasets import layout
from kubric.datasets.layout import DatasetError
from kubric.io.json_io import read_json, write_json

PROGRESS_FILE = "progress.json"


def work_dir(out: pathlib.Path) -> pathlib.Path:
    """The work folder of a pack into ``out``: ``.NAME.incomplete`` beside it."""
    return out.parent / f".{out.name}.incomplete"


def open_work(work: pathlib.Path, plan_key: str) -> dict:
    """The work directory's progress (fresh unless it was made for the same plan)."""
    progress_path = work / PROGRESS_FILE
    if progress_path.is_file():
        try:
            state = read_json(progress_path)
            keep = {sh["file"] for shards in state["shards"].values() for sh in shards}
        except (ValueError, KeyError, TypeError, AttributeError):
            state, keep = {}, set()
        # trusted only when every file it names is there (not renamed or removed since)
        if state.get("plan") == plan_key and all((work / f).is_file() for f in keep if f):
            for entry in work.iterdir():  # drop a shard that was being written
                if entry.name != PROGRESS_FILE and entry.name not in keep:
                    if entry.is_dir() and not entry.is_symlink():
                        shutil.rmtree(entry)
                    else:
                        entry.unlink()
            return state
    if work.is_symlink() or work.is_file():
        work.unlink()
    elif work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    state = {"plan": plan_key, "shards": {}}
    write_json(state, progress_path)
    return state


def done_names(state: dict, split: str) -> set[str]:
    done = set()
    for shard in state["shards"].get(split, []):
        done.update(shard["scenes"])
        done.update(pathlib.Path(p).name for p, _ in shard.get("corrupt", []))
    return done


class ShardWriter:
    """One shard being written (a temporary name until finished)."""

    def __init__(self, work: pathlib.Path, name: str, split: str, index: int):
        from array_record.python import array_record_module
        self.split, self.index = split, index
        self.file = f"{name}-{split}.part-{index:05d}"
        self.path = work / self.file
        with self._errors_named():
            self._writer = array_record_module.ArrayRecordWriter(
                str(self.path), layout.SHARD_WRITER_OPTIONS)
        self.scenes: list[str] = []
        self.corrupt: list[tuple[str, str]] = []
        self.num_bytes = 0

    @contextlib.contextmanager
    def _errors_named(self):
        """A failed write (a full disk: array_record says only "Failed to write") names the
        shard and the reason."""
        try:
            yield
        except (OSError, RuntimeError, ValueError) as err:
            reason = err.strerror if isinstance(err, OSError) and err.strerror else \
                " ".join(str(err).split())[:300]
            free = shutil.disk_usage(self.path.parent).free
            raise DatasetError(f"{str(self.path)!r}: cannot write the shard: {reason} "
                               f"({free / 2**20:.0f} MiB free there)") from None

    def add(self, scene_name: str, data: bytes) -> None:
        with self._errors_named():
            faults.point("pack.shard_write", self.path)
            self._writer.write(data)
        self.scenes.append(scene_name)
        self.num_bytes += len(data)

    def close(self) -> None:
        with self._errors_named():
            self._writer.close()

    def abandon(self) -> None:
        with contextlib.suppress(Exception):
            self._writer.close()
        self.path.unlink(missing_ok=True)


def finish_shard(work: pathlib.Path, state: dict, writer: ShardWriter) -> None:
    writer.close()
    if not writer.scenes:
        writer.path.unlink()
    state["shards"].setdefault(writer.split, []).append(
        {"file": writer.file if writer.scenes else "", "scenes": writer.scenes,
         "corrupt": writer.corrupt, "num_bytes": writer.num_bytes})
    write_json(state, work / PROGRESS_FILE)


def finalise(work, state, schema, name, dims, split_fractions, incomplete, features,
             hash_files: bool = True) -> dict:
    """Final shard names, TFDS metadata and the kubric marker; returns counts per split. A
    shard's checksum and size are its state entry's ``sha256`` and ``file_bytes``, else
    (``hash_files``) its file's."""
    import tensorflow_datasets as tfds

    from kubric import __version__
    split_infos, counts, scenes, shard_lengths, digests, sizes = [], {}, {}, {}, {}, {}
    # the record goes before the renames: a kill among them leaves no record naming moved files
    # (the next run starts afresh), never one that a rerun would trust
    (work / PROGRESS_FILE).unlink()
    for split in split_fractions:
        shards = [sh for sh in state["shards"].get(split, []) if sh["scenes"]]
        for i, shard in enumerate(shards):
            final = layout.shard_name(name, split, i, len(shards))
            os.replace(work / shard["file"], work / final)
            faults.point("pack.shard_renamed")
            digest = shard.get("sha256") or (layout.file_sha256(work / final) if hash_files
                                             else None)
            if digest:
                digests[final] = digest
            file_bytes = shard.get("file_bytes") or \
                ((work / final).stat().st_size if hash_files else None)
            if file_bytes:
                sizes[final] = file_bytes
        counts[split] = sum(len(sh["scenes"]) for sh in shards)
        scenes[split] = [s for sh in shards for s in sh["scenes"]]
        shard_lengths[split] = [len(sh["scenes"]) for sh in shards]
        if shards:
            split_infos.append(tfds.core.SplitInfo(
                name=split, shard_lengths=[len(sh["scenes"]) for sh in shards],
                num_bytes=sum(sh["num_bytes"] for sh in shards)))
    tfds.folder_dataset.write_metadata(
        data_dir=str(work), features=features, split_infos=split_infos, check_data=False,
        description=f"Kubric {schema.name} scenes packed by kubric {__version__}. "
                    f"{schema.description}",
        homepage="https://github.com/google-research/kubric")
    write_json({"format": layout.FORMAT, "format_version": layout.FORMAT_VERSION,
                "name": name, "schema": schema.name, "schema_version": schema.version,
                "dims": dims, "splits": split_fractions, "counts": counts,
                "shard_lengths": shard_lengths, "scenes": scenes,
                "incomplete_skipped": incomplete, "kubric_version": __version__,
                "shard_writer_options": layout.SHARD_WRITER_OPTIONS,
                "shard_sha256": digests, "shard_bytes": sizes,
                "schema_json": schema.to_json()},
               work / layout.INFO_FILE)
    return counts


def swap_into_place(work: pathlib.Path, out: pathlib.Path) -> None:
    """Rename the finished work directory to ``out``, replacing an old dataset (checked to hold
    only packer files) or an empty directory. The old one is first renamed to ``.NAME.old`` (a
    fixed name: one left by a kill here is removed by the next pack) and then deleted."""
    faults.point("pack.before_swap")
    old = out.parent / f".{out.name}.old"
    if old.exists() or old.is_symlink():
        _remove(old)
    if out.exists():
        os.replace(out, old)
        faults.point("pack.old_moved")
    os.replace(work, out)
    if old.exists():
        _remove(old)


def _remove(path: pathlib.Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink()
