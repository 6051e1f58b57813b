"""``kubric worker``, ``kubric generate``, ``kubric recipes`` and ``kubric inspect``."""

from __future__ import annotations

import ctypes
import math
import os
import signal
import sys

from kubric.io import storage
from kubric.pipeline.cleanup import handle_termination, private_tmpdir
from kubric.pipeline.dask_runner import (
    ClusterError,  # no Dask import
    ClusterOptions,
)
from kubric.pipeline.inspect import inspect_scene
from kubric.pipeline.options import OptionError
from kubric.pipeline.recipe import get_recipe, load_builtin, recipe_spec
from kubric.pipeline.runner import PARENT_ENV, LocalRunner
from kubric.pipeline.worker import run_scene

#: the largest seed: numpy's RandomState (and so every recipe's rng) takes seeds < 2**32
MAX_SEED = 2**32 - 1


def _error(command: str, message) -> int:
    print(f"kubric {command}: error: {message}", file=sys.stderr)
    return 2


def _die_with_parent() -> None:
    """When started by the local runner, die with it (Linux parent-death signal)."""
    pid = os.environ.pop(PARENT_ENV, None)
    if not pid:
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != int(pid):
        sys.exit(143)


def cmd_worker(args) -> int:
    _die_with_parent()
    os.environ.setdefault("KUBRIC_RENDER_PROGRESS", "0")  # no frame bar in a scene's log
    handle_termination()  # SIGTERM like SIGINT: unwind, remove the work directory
    seed = args.seed if args.seed is not None else args.first_seed + args.index
    if args.recipe_path:
        sys.path.insert(0, args.recipe_path)
    if not 0 <= seed <= MAX_SEED:
        return _error("worker", f"seed must be in 0..{MAX_SEED} (2**32 - 1), got {seed}")
    try:
        recipe = get_recipe(args.recipe).from_assignments(args.set)
    except OptionError as err:
        return _error("worker", err)
    try:
        out = storage.normalise(args.out)
        if not storage.is_url(out):
            storage.check_writable(out)
    except storage.StorageError as err:
        return _error("worker", err)
    private_tmpdir()  # Blender's session folders and every temporary file go with this process
    if storage.is_url(out):
        from kubric.pipeline.remote import run_scene_remote
        result = run_scene_remote(recipe, seed, out,
                                  echo=lambda line: print(line, flush=True))
    else:
        result = run_scene(recipe, seed, args.out)
    # The scene is complete: a late SIGTERM / SIGINT must not interrupt the interpreter's (and
    # Blender's own) shutdown code, which would print a traceback from inside bpy.
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, signal.SIG_IGN)
    print(f"{result.status}: {result.path} ({result.seconds:.1f} s)", flush=True)
    return 0


#: cluster flags → their defaults; the slurm ones apply to --cluster slurm only
CLUSTER_FLAGS = {"threads_per_scene": 1, "connect_timeout": 20.0,
                 "dashboard_address": "127.0.0.1:8787"}
SLURM_FLAGS = {"jobs": 1, "cores_per_job": 1, "memory": "4GB", "walltime": "01:00:00",
               "queue": None, "job_directive": [], "print_job_script": False}


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def misplaced_flag(args) -> str | None:
    """A one-line complaint about a flag given where it means nothing, or None."""
    given = [n for n in (*CLUSTER_FLAGS, *SLURM_FLAGS) if getattr(args, n) not in (None, False)]
    if args.cluster is None:
        return f"{_flag(given[0])} needs --cluster" if given else None
    slurm_only = [n for n in given if n in SLURM_FLAGS]
    if args.cluster != "slurm" and slurm_only:
        return f"{_flag(slurm_only[0])} applies to --cluster slurm only"
    if args.cluster not in ("local", "slurm"):
        for name in ("workers", "dashboard_address"):
            if getattr(args, name) is not None:
                return (f"{_flag(name)} does not apply to a running scheduler ({args.cluster}): "
                        f"its workers and dashboard are started with it")
    if args.cluster == "slurm" and args.workers is not None:
        return "--workers does not apply to --cluster slurm (use --jobs and --cores-per-job)"
    return None


def cluster_options(args):
    value = {n: d if getattr(args, n) is None else getattr(args, n)
             for n, d in {**CLUSTER_FLAGS, **SLURM_FLAGS}.items()}
    return ClusterOptions(spec=args.cluster, workers=args.workers,
                          threads_per_scene=value["threads_per_scene"],
                          connect_timeout=value["connect_timeout"],
                          dashboard_address=value["dashboard_address"], jobs=value["jobs"],
                          cores_per_job=value["cores_per_job"], memory=value["memory"],
                          walltime=value["walltime"], queue=value["queue"],
                          job_directives=value["job_directive"])


def cmd_generate(args) -> int:
    if args.scenes < 1:
        return _error("generate", f"--scenes must be ≥ 1, got {args.scenes}")
    if args.first_seed < 0:
        return _error("generate", f"--first-seed must be ≥ 0, got {args.first_seed}")
    if args.first_seed + args.scenes - 1 > MAX_SEED:
        return _error("generate", f"--first-seed {args.first_seed} + --scenes {args.scenes}: the "
                      f"last seed {args.first_seed + args.scenes - 1} is above {MAX_SEED} "
                      f"(2**32 - 1, the largest seed)")
    if args.workers is not None and args.workers < 1:
        return _error("generate", f"--workers must be ≥ 1, got {args.workers}")
    if args.retries < 0:
        return _error("generate", f"--retries must be ≥ 0, got {args.retries}")
    if args.timeout is not None and not (math.isfinite(args.timeout) and args.timeout > 0):
        return _error("generate", f"--timeout must be a finite number of seconds > 0, got {args.timeout}")
    misplaced = misplaced_flag(args)
    if misplaced:
        return _error("generate", misplaced)
    cluster_opts = None
    if args.cluster is not None:
        from kubric.pipeline.dask_runner import slurm_job_script
        cluster_opts = cluster_options(args)
        try:
            cluster_opts.validate()
        except ClusterError as err:
            return _error("generate", err)
        if args.print_job_script:
            print(slurm_job_script(cluster_opts))
            return 0
    handle_termination()  # until the runner installs its own (stop, end the workers, clean up)
    private_tmpdir()  # the workers' temporary folders nest in it: all go when this process ends
    try:
        cls = get_recipe(args.recipe)
        cls.from_assignments(args.set).prepare()
    except OptionError as err:
        return _error("generate", err)
    try:
        out = storage.normalise(args.out)
        if out.startswith("memory://"):
            raise storage.StorageError(f"--out {args.out!r}: an in-memory filesystem is private to "
                                       f"one process, and every scene runs in its own process; "
                                       f"use a directory or an object store URL")
        storage.check_writable(out)
    except storage.StorageError as err:
        return _error("generate", err)
    seeds = range(args.first_seed, args.first_seed + args.scenes)
    resume = "overwrite" if args.overwrite else "any" if args.resume_any else "same"
    common = dict(assignments=args.set, retries=args.retries, timeout=args.timeout,
                  progress=not args.no_progress, resume=resume)
    client = cluster = None
    if cluster_opts is None:
        runner = LocalRunner(recipe_spec(cls), out, seeds, workers=args.workers, **common)
    else:
        from kubric.pipeline.dask_runner import DaskRunner, open_cluster
        try:
            client, cluster = open_cluster(cluster_opts)
        except ClusterError as err:
            return _error("generate", err)
        from kubric.pipeline.dask_runner import dashboard_link
        print(f"Dask dashboard: {dashboard_link(client, cluster, cluster_opts)}", flush=True)
        from kubric.pipeline.dask_slots import SceneSlots
        print(f"Dask slots: {SceneSlots(client, cluster_opts.threads_per_scene).describe()}",
              flush=True)
        runner = DaskRunner(recipe_spec(cls), out, seeds, client,
                            threads_per_scene=cluster_opts.threads_per_scene, **common)
    try:
        summary = runner.run()
    except ClusterError as err:  # the scheduler went away mid-run
        return _error("generate", err)
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    print(summary.format(runner.out_root))
    if summary.interrupted:
        return 130
    return 0 if summary.ok else 1


def format_recipe(cls) -> str:
    internal = " [internal: a test tool, not a dataset]" \
        if cls.internal else ""
    lines = [f"{cls.name}: {cls.description()}{internal}"]
    width = max((len(n) for n in cls.options), default=0)
    for name, opt in cls.options.items():
        bounded = opt.choices is not None or any(
            v is not None for v in (opt.low, opt.high, opt.limit))
        bounds = f" [allowed: {opt.allowed()}]" if bounded else ""
        lines.append(f"    {name:<{width}}  {opt.type_name:<11} default {opt.default!r}: "
                     f"{opt.help}{bounds}")
    return "\n".join(lines)


def cmd_recipes(args) -> int:
    try:
        classes = [get_recipe(args.name)] if args.name else \
            sorted(load_builtin().values(), key=lambda c: (c.internal, c.name))
    except OptionError as err:
        return _error("recipes", err)
    print("\n\n".join(format_recipe(cls) for cls in classes))
    return 0


def cmd_inspect(args) -> int:
    try:
        if storage.is_url(args.scene_dir):
            from kubric.pipeline.inspect import inspect_url
            report = inspect_url(args.scene_dir, args.sheet)
        else:
            report = inspect_scene(args.scene_dir, args.sheet)
    except FileNotFoundError as err:  # no such scene: a usage error; bad data raises on (exit 1)
        return _error("inspect", err)
    print(report)
    return 0


def add_cluster_arguments(p, what: str) -> None:
    """The ``--cluster`` flags (of ``generate`` and ``pack``); ``what`` is --cluster's help."""
    g = p.add_argument_group("Dask cluster (kubric.pipeline.dask_runner)")
    g.add_argument("--cluster", default=None, metavar="local|tcp://HOST:PORT|slurm",
                   help=what)
    g.add_argument("--threads-per-scene", type=int, default=None,
                   help="render threads of each scene (one scene per worker slot; default 1)")
    g.add_argument("--connect-timeout", type=float, default=None,
                   help="seconds to wait for the scheduler (default 20)")
    g.add_argument("--dashboard-address", default=None,
                   help="dashboard address of a cluster started here (default 127.0.0.1:8787: "
                   "this machine only; :8787 listens on every interface)")
    g.add_argument("--jobs", type=int, default=None, help="slurm: worker jobs to submit")
    g.add_argument("--cores-per-job", type=int, default=None, help="slurm: cores of each job")
    g.add_argument("--memory", default=None, help="slurm: memory of each job (default 4GB)")
    g.add_argument("--walltime", default=None, help="slurm: time limit of each job")
    g.add_argument("--queue", default=None, help="slurm: partition")
    g.add_argument("--job-directive", action="append", default=None, metavar="DIRECTIVE",
                   help="slurm: extra #SBATCH line, e.g. --job-directive=--gres=gpu:1 "
                   "(repeatable)")
    g.add_argument("--print-job-script", action="store_true",
                   help="slurm: print the worker job script and exit (submits nothing)")


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("worker", help="generate one scene (one seed) with a recipe",
                              description="Write OUT/scene_{seed:08d}/ atomically (_SUCCESS "
                              "last); a complete scene is skipped.")
    p.add_argument("recipe", help="recipe name (see `kubric recipes`), module:Class or "
                   "file.py:Class")
    seed = p.add_mutually_exclusive_group(required=True)
    seed.add_argument("--seed", type=int, help="the scene's seed (determines the scene)")
    seed.add_argument("--index", type=int, help="array-job index (e.g. $SLURM_ARRAY_TASK_ID or "
                      "$JOB_COMPLETION_INDEX): seed = --first-seed + index")
    p.add_argument("--first-seed", type=int, default=0, help="seed of index 0 (default 0)")
    p.add_argument("--out", required=True, help="output root: a directory or an fsspec URL "
                   "(the scene renders into local scratch and is uploaded, _SUCCESS last)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="recipe option (repeatable)")
    p.add_argument("--recipe-path", default=None, metavar="DIR", help="a folder put first on "
                   "the module path to import a module:Class recipe from (generate passes it)")
    p.set_defaults(func=cmd_worker)

    p = subparsers.add_parser("generate", help="generate many scenes (process pool or Dask)",
                              description="One fresh worker process per scene; resumable. "
                              "Default: a local process pool; --cluster runs the same workers "
                              "as Dask tasks.")
    p.add_argument("recipe")
    p.add_argument("--out", required=True, help="output root: a directory or an fsspec URL "
                   "(s3://bucket/run, gs://..., file://...; not memory://, which is private "
                   "to one process)")
    p.add_argument("--scenes", type=int, required=True, help="number of scenes")
    p.add_argument("--first-seed", type=int, default=0, help="seed of the first scene")
    p.add_argument("--workers", type=int, default=None, help="parallel workers (default: cores; "
                   "with --cluster local: cores // --threads-per-scene)")
    p.add_argument("--retries", type=int, default=2, help="extra attempts per failed scene")
    p.add_argument("--timeout", type=float, default=None, help="seconds per worker attempt")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="recipe option, repeatable (`kubric recipes NAME` lists a recipe's "
                   "options, types and defaults), e.g. --set resolution=128x128 "
                   "--set quality=fast")
    again = p.add_mutually_exclusive_group()
    again.add_argument("--overwrite", action="store_true", help="make the requested seeds "
                       "again: their complete scenes in --out are deleted first")
    again.add_argument("--resume-any", action="store_true", help="skip the complete scenes in "
                       "--out even when other options made them (by default a re-run whose "
                       "options differ from theirs refuses)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_cluster_arguments(p, "run on Dask: a LocalCluster, a running scheduler, or Slurm jobs")
    p.set_defaults(func=cmd_generate)

    p = subparsers.add_parser("recipes", help="list recipes and their options")
    p.add_argument("name", nargs="?", help="only this recipe")
    p.set_defaults(func=cmd_recipes)

    p = subparsers.add_parser("inspect", help="summarise a scene directory, write a contact sheet")
    p.add_argument("scene_dir", help="a scene directory or its URL (s3://.../scene_00000000)")
    p.add_argument("--sheet", default=None, help="contact sheet path (default: "
                   "./SCENE_contact_sheet.png in the current directory, never inside the scene; "
                   ".gif for an animation)")
    p.set_defaults(func=cmd_inspect)


__all__ = ["add_parser", "add_cluster_arguments"]
