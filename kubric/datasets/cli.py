"""``kubric pack`` and ``kubric datasets info|schema``."""

from __future__ import annotations

import sys

from kubric.datasets.dask_pack import DaskExecutor
from kubric.datasets.info import dataset_info
from kubric.datasets.layout import DatasetError
from kubric.datasets.packer import pack, read_class_names
from kubric.datasets.store_commit import pack_into
from kubric.errors import KubricError
from kubric.extras import require
from kubric.io import storage
from kubric.io.schema import SchemaError, schema_markdown
from kubric.pipeline.cleanup import handle_termination, private_tmpdir
from kubric.pipeline.cli import add_cluster_arguments, cluster_options, misplaced_flag
from kubric.pipeline.dask_runner import ClusterError, dashboard_link, open_cluster, slurm_job_script
from kubric.pipeline.recipe import schema_of


def _error(command: str, message, code: int | None = None) -> int:
    """Print the one-line error; the exit status is the error's own (a
    :class:`~kubric.errors.KubricError`: 2 for a usage error such as
    :class:`~kubric.datasets.layout.DatasetUsageError`, 1 for bad input data), else 2."""
    if code is None:
        code = message.exit_code if isinstance(message, KubricError) else 2
    print(f"kubric {command}: error: {message}", file=sys.stderr)
    return code


def cmd_pack(args) -> int:
    common = dict(name=args.name, splits=args.splits, schema=args.schema,
                  workers=1 if args.workers is None else args.workers,
                  examples_per_shard=args.examples_per_shard, progress=not args.no_progress,
                  verify=args.verify, overwrite=args.overwrite)
    misplaced = misplaced_flag(args)
    if misplaced:
        return _error("pack", misplaced)
    require("kubric pack", "tensorflow_datasets", "array_record")  # before any scene is read
    try:
        common["class_names"] = read_class_names(args.class_names)
    except DatasetError as err:
        return _error("pack", err)
    handle_termination()  # SIGTERM like Ctrl-C: unwind, end the pool's workers
    private_tmpdir()  # temporary files (Dask's scratch space too) go when this process ends
    if args.cluster is not None:
        return _pack_on_cluster(args, common)
    try:
        if storage.is_url(args.scenes_dir) or storage.is_url(args.out):
            from kubric.datasets.store_commit import pack_into
            result = pack_into(args.scenes_dir, args.out, **common)
        else:
            result = pack(args.scenes_dir, args.out, **common)
    except (DatasetError, SchemaError) as err:
        return _error("pack", err)
    return _report(args, result)


def _pack_on_cluster(args, common: dict) -> int:
    options = cluster_options(args)
    try:
        options.validate()
    except ClusterError as err:
        return _error("pack", err)
    if args.print_job_script:
        print(slurm_job_script(options))
        return 0
    common["workers"] = 1  # the cluster's slots do the work
    try:
        client, cluster = open_cluster(options, processes=True)
    except ClusterError as err:
        return _error("pack", err)
    print(f"Dask dashboard: {dashboard_link(client, cluster, options)}", flush=True)
    try:
        result = pack_into(args.scenes_dir, args.out, executor=DaskExecutor(client), **common)
    except (DatasetError, SchemaError) as err:
        return _error("pack", err)
    except Exception:
        from kubric.pipeline.dask_runner import scheduler_lost
        lost = scheduler_lost(client, "finished chunks are kept (nothing is published)")
        if lost is None:
            raise
        return _error("pack", lost)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return _report(args, result)


def _report(args, result) -> int:
    print(result.format())
    if args.verify:
        print(f"verified: every example equals its scene directory ({sum(result.counts.values())}"
              " examples)")
    return 0


def cmd_info(args) -> int:
    try:
        print(dataset_info(args.dataset_dir))
    except DatasetError as err:
        return _error("datasets info", err)
    return 0


def cmd_schema(args) -> int:
    try:
        print(schema_markdown(schema_of(args.recipe)), end="")
    except SchemaError as err:
        return _error("datasets schema", err)
    return 0


def cmd_card(args) -> int:
    import importlib
    card = importlib.import_module("kubric.datasets.exports.hub.card")  # the layer above
    try:
        out = card.write_card(args.dataset_dir, args.out, args.scenes,
                              progress=not args.no_progress)
    except (KubricError, OSError) as err:
        return _error("datasets card", err)
    print(f"wrote the dataset card {out / 'README.md'}")
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "pack", help="pack scene directories into a TFDS-layout dataset (no TensorFlow)",
        description="Write DATASET_DIR (dataset_info.json, features.json, "
        "NAME-SPLIT.array_record-0000k-of-0000n shards, kubric_dataset.json) from the complete "
        "scenes of SCENES_DIR. Resumable; the output appears only when complete.")
    p.add_argument("scenes_dir", metavar="SCENES_DIR", help="a directory of scenes or its URL "
                   "(s3://bucket/run, gs://..., any fsspec URL)")
    p.add_argument("--out", required=True, metavar="DATASET_DIR",
                   help="a directory, or a URL (s3://bucket/ds, gs://..., file://...: written "
                   "through a commit protocol, kubric_dataset.json last)")
    p.add_argument("--name", default=None, help="dataset name (default: the recipe name)")
    p.add_argument("--splits", default="train=0.9,validation=0.1",
                   help="NAME=FRACTION,... summing to 1 (default train=0.9,validation=0.1); a "
                   "scene's split is a fixed function of its seed")
    p.add_argument("--workers", type=int, default=None, help="encoding processes (default 1; "
                   "with --cluster local: the LocalCluster's worker processes)")
    p.add_argument("--schema", default=None, help="schema or recipe name, or FILE.py:Class "
                   "(default: the schema the scenes store in schema.json)")
    p.add_argument("--examples-per-shard", type=int, default=256)
    p.add_argument("--verify", action="store_true",
                   help="re-read every example and compare it with its scene directory")
    p.add_argument("--overwrite", action="store_true", help="replace an existing dataset")
    p.add_argument("--class-names", action="append", default=[], metavar="FEATURE=FILE",
                   help="names (one per line) of a class label otherwise collected from the "
                   "scenes, e.g. instances/category=OTHER_DATASET/instances-category.labels.txt "
                   "so that both datasets share category ids (repeatable)")
    p.add_argument("--no-progress", action="store_true")
    add_cluster_arguments(p, "pack on Dask, one task per shard (kubric.datasets.dask_pack): a "
                          "LocalCluster, a running scheduler, or Slurm jobs")
    p.set_defaults(func=cmd_pack)

    p = subparsers.add_parser("datasets", help="packed datasets: info, schema, card")
    sub = p.add_subparsers(dest="datasets_command", metavar="SUBCOMMAND", required=True)
    q = sub.add_parser("info", help="splits, counts, features with shapes, size on disk")
    q.add_argument("dataset_dir", metavar="DATASET_DIR")
    q.set_defaults(func=cmd_info)
    q = sub.add_parser("schema", help="a recipe's output contract as a Markdown table")
    q.add_argument("recipe")
    q.set_defaults(func=cmd_schema)
    q = sub.add_parser("card", help="the dataset card: counts, histograms, contact sheet, "
                       "licences (Markdown + PNG)")
    q.add_argument("dataset_dir", metavar="DATASET_DIR")
    q.add_argument("--out", required=True, help="the card's folder (README.md, card/*.png)")
    q.add_argument("--scenes", default=None, metavar="SCENES_DIR", help="the scene folders it "
                   "was packed from: licences, attribution, command, versions")
    q.add_argument("--no-progress", action="store_true")
    q.set_defaults(func=cmd_card)


__all__ = ["add_parser"]
