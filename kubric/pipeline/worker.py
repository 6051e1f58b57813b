"""Running one recipe for one seed into an atomic scene directory.

Layout under the output root ``DIR``:

* ``DIR/scene_{seed:08d}/`` — a scene; complete only when it contains ``_SUCCESS``;
* ``DIR/.scene_{seed:08d}.incomplete-{pid}/`` — work in progress of process ``pid``.

:func:`run_scene` writes into the work directory, writes ``_SUCCESS`` there when the recipe
returns (last, with :func:`write_success`), and then renames the work directory to the final name
— one atomic step, so the final name appears complete or not at all. A complete scene is never
touched again (skipped); an incomplete final directory (a leftover of an older layout or a manual
copy), or a work directory whose process is gone, is removed and the scene redone.
"""

from __future__ import annotations

import errno
import os
import pathlib
import shutil
import time
from dataclasses import dataclass

from kubric import (
    faults,
    randomness,  # here, not at module level: it imports the asset sources
)
from kubric.io.scene_dir import (
    SUCCESS_FILE,
    is_complete,
    parse_work_dir,
    scene_name,
    work_dir_name,
    write_success,
)
from kubric.io.stored_schema import check_declared
from kubric.pipeline.cleanup import own, pid_alive, release

SUCCESS = SUCCESS_FILE  # the completion marker's name (kubric.io.scene_dir)


def stale_work_dirs(out_root: pathlib.Path, seed: int | None = None) -> list[pathlib.Path]:
    """Work directories (of ``seed``, or of any seed) whose process no longer runs."""
    out_root = pathlib.Path(out_root)
    if not out_root.is_dir():
        return []
    stale = []
    for entry in out_root.iterdir():
        parsed = parse_work_dir(entry.name)
        if not parsed or (seed is not None and parsed[0] != scene_name(seed)):
            continue
        if not pid_alive(parsed[1]):
            stale.append(entry)
    return sorted(stale)


def remove_stale(out_root: pathlib.Path, seed: int | None = None) -> list[pathlib.Path]:
    """Delete stale work directories (see :func:`stale_work_dirs`); returns what was removed."""
    removed = stale_work_dirs(out_root, seed)
    for path in removed:
        shutil.rmtree(path, ignore_errors=True)
    return removed


@dataclass
class SceneResult:
    seed: int
    path: pathlib.Path
    status: str          # "done" or "skipped"
    seconds: float


def run_scene(recipe, seed: int, out_root) -> SceneResult:
    """Generate scene ``seed`` with ``recipe`` (a :class:`~kubric.pipeline.recipe.Recipe`
    instance) under ``out_root`` atomically (see module doc)."""
    start = time.time()
    out_root = pathlib.Path(out_root)
    final = out_root / scene_name(seed)
    if is_complete(final):
        return SceneResult(seed, final, "skipped", 0.0)
    if final.is_symlink():
        raise FileExistsError(errno.EEXIST, "a symbolic link stands at the scene's name; "
                              "remove it (a scene directory is written there)", str(final))
    out_root.mkdir(parents=True, exist_ok=True)
    remove_stale(out_root, seed)
    work = out_root / work_dir_name(seed, os.getpid())
    if work.exists():
        shutil.rmtree(work)
    work.mkdir()
    own(work)  # removed at exit even when Blender turns a signal into an immediate exit
    try:
        with randomness.explicit_rng_only(f"recipe {recipe.name!r}"):  # rng= always explicit
            try:
                recipe.generate(seed, work)
                check_declared(work)  # nothing written around write_scene after it ran
                faults.point("worker.generated")
            except OSError as err:
                if err.filename is None and err.errno in (errno.ENOSPC, errno.EDQUOT):
                    free = shutil.disk_usage(out_root).free / 2**20
                    raise OSError(err.errno, f"{err.strerror} (writing the scene; {free:.0f} "
                                  "MiB free there)", str(work)) from None
                raise
        if is_complete(final):  # another process finished the same seed meanwhile
            shutil.rmtree(work, ignore_errors=True)
            return SceneResult(seed, final, "skipped", time.time() - start)
        seconds = time.time() - start
        write_success(work, recipe=recipe.name, seed=int(seed), seconds=round(seconds, 3))
        if final.exists():  # an incomplete leftover (no _SUCCESS)
            shutil.rmtree(final)
        os.rename(work, final)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    finally:
        if not work.exists():  # renamed or removed; a removal cut short stays owned (atexit)
            release(work)
    return SceneResult(seed, final, "done", seconds)
