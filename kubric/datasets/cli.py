"""``kubric pack`` and ``kubric datasets info|schema``."""

from __future__ import annotations

import sys


def _error(command: str, message) -> int:
    print(f"kubric {command}: error: {message}", file=sys.stderr)
    return 2


def cmd_pack(args) -> int:
    from kubric.datasets.layout import DatasetError
    from kubric.datasets.packer import pack, read_class_names
    from kubric.io.schema import SchemaError
    try:
        class_names = read_class_names(args.class_names)
        result = pack(args.scenes_dir, args.out, name=args.name, splits=args.splits,
                      workers=args.workers, schema=args.schema,
                      examples_per_shard=args.examples_per_shard,
                      progress=not args.no_progress, verify=args.verify,
                      overwrite=args.overwrite, class_names=class_names)
    except (DatasetError, SchemaError) as err:
        return _error("pack", err)
    print(result.format())
    if args.verify:
        print(f"verified: every example equals its scene directory ({sum(result.counts.values())}"
              " examples)")
    return 0


def cmd_info(args) -> int:
    from kubric.datasets.info import dataset_info
    from kubric.datasets.layout import DatasetError
    try:
        print(dataset_info(args.dataset_dir))
    except DatasetError as err:
        return _error("datasets info", err)
    return 0


def cmd_schema(args) -> int:
    from kubric.io.schema import SchemaError, get_schema, schema_markdown
    try:
        print(schema_markdown(get_schema(args.recipe)), end="")
    except SchemaError as err:
        return _error("datasets schema", err)
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "pack", help="pack scene directories into a TFDS-layout dataset (no TensorFlow)",
        description="Write DATASET_DIR (dataset_info.json, features.json, "
        "NAME-SPLIT.array_record-0000k-of-0000n shards, kubric_dataset.json) from the complete "
        "scenes of SCENES_DIR. Resumable; the output appears only when complete.")
    p.add_argument("scenes_dir", metavar="SCENES_DIR")
    p.add_argument("--out", required=True, metavar="DATASET_DIR")
    p.add_argument("--name", default=None, help="dataset name (default: the recipe name)")
    p.add_argument("--splits", default="train=0.9,validation=0.1",
                   help="NAME=FRACTION,... summing to 1 (default train=0.9,validation=0.1); a "
                   "scene's split is a fixed function of its seed")
    p.add_argument("--workers", type=int, default=1, help="encoding processes (default 1)")
    p.add_argument("--schema", default=None, help="recipe schema (default: the scenes' recipe)")
    p.add_argument("--examples-per-shard", type=int, default=256)
    p.add_argument("--verify", action="store_true",
                   help="re-read every example and compare it with its scene directory")
    p.add_argument("--overwrite", action="store_true", help="replace an existing dataset")
    p.add_argument("--class-names", action="append", default=[], metavar="FEATURE=FILE",
                   help="names (one per line) of a class label otherwise collected from the "
                   "scenes, e.g. instances/category=OTHER_DATASET/instances-category.labels.txt "
                   "so that both datasets share category ids (repeatable)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=cmd_pack)

    p = subparsers.add_parser("datasets", help="packed datasets: info, schema")
    sub = p.add_subparsers(dest="datasets_command", metavar="SUBCOMMAND", required=True)
    q = sub.add_parser("info", help="splits, counts, features with shapes, size on disk")
    q.add_argument("dataset_dir", metavar="DATASET_DIR")
    q.set_defaults(func=cmd_info)
    q = sub.add_parser("schema", help="a recipe's output contract as a Markdown table")
    q.add_argument("recipe")
    q.set_defaults(func=cmd_schema)


__all__ = ["add_parser"]
