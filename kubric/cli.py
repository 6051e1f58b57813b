"""The ``kubric`` command. Each sub-command lives in its own module, which defines
``add_parser(subparsers)`` registering a parser whose ``func(args) -> int`` runs it."""

from __future__ import annotations

import argparse
import importlib
import sys

#: sub-command modules, in the order ``kubric --help`` lists them.
SUBCOMMAND_MODULES = (
    "kubric.pipeline.cli",
    "kubric.assets.cli",
    "kubric.annotations.tracks_cli",
    "kubric.datasets.cli",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="kubric", description="Kubric: generate synthetic computer-vision datasets (scene "
        "recipes, local runner, asset sources, scene inspection, packed datasets).")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name != name:
                raise
            continue
        module.add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
