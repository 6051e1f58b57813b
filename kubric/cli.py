"""The ``kubric`` command. Each sub-command lives in its own module, which defines
``add_parser(subparsers)`` registering a parser whose ``func(args) -> int`` runs it.

Errors: :func:`main` is the one top-level handler. An expected error (a
:class:`~kubric.errors.KubricError`: a bad option, invalid input data, ...; or an ``OSError``: a
missing or unreadable file, a full disk) prints one line
``kubric <command>: error: <message>`` on stderr and exits with the error's status
(docs/exit-codes.md: 2 for a usage error or a refused output, 1 for a failure, 3 for a busy
output); the traceback is printed only with the global ``--debug`` flag (or
``KUBRIC_DEBUG=1``). Ctrl-C exits 130 with one line, SIGTERM 143 after the same unwinding.
Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import traceback

from kubric.errors import KubricError
from kubric.extras import missing_extra

#: sub-command modules, in the order ``kubric --help`` lists them.
SUBCOMMAND_MODULES = (
    "kubric.pipeline.cli",
    "kubric.asset_tools.cli",
    "kubric.datasets.exports.cli",
    "kubric.datasets.cli",
    "kubric.viewer.cli",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="kubric", description="Kubric: generate synthetic computer-vision datasets (scene "
        "recipes, local runner, asset sources, scene inspection, packed datasets).")
    parser.add_argument("--debug", action="store_true", help="print the traceback of an error "
                        "(default: one line; also KUBRIC_DEBUG=1)")
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


def error_line(err: BaseException) -> str:
    """The one-line message of ``err`` (an OSError's path included)."""
    if missing_extra(err):
        return missing_extra(err)
    if isinstance(err, OSError) and err.strerror and err.filename is not None:
        target = f" -> {err.filename2}" if err.filename2 is not None else ""
        message = f"{err.filename}{target}: {err.strerror}"
    elif isinstance(err, OSError) and err.strerror and str(err).startswith("[Errno"):
        message = err.strerror  # no path known: the bare reason, without "[Errno N]"
    elif isinstance(err, MemoryError):
        detail = f" ({err})" if str(err) else ""
        message = (f"out of memory{detail}: lower the resolution, frames or workers, or give "
                   "this process more memory")
    else:
        message = str(err) or type(err).__name__
    return " ".join(message.split())


def exit_code(err: BaseException) -> int | None:
    """The exit status of an expected error (:class:`~kubric.errors.KubricError`'s own; 1 for an
    OSError: a path and its reason), None for a bug (which keeps its traceback)."""
    if isinstance(err, KubricError):
        return err.exit_code
    if missing_extra(err):  # an optional package not installed: its extra named in one line
        return 1
    if isinstance(err, OSError | MemoryError):  # a MemoryError: the machine's limit, not a bug
        return 1
    return None


#: the commands whose ``--out`` may be a URL (object storage); every other ``--out`` is local
URL_OUTPUTS = frozenset({"generate", "worker", "pack"})


def check_local_output(args) -> None:
    """Refuse (exit 2, one line) an ``--out`` URL given to a command that writes local files
    only, before the command runs: it would otherwise become a local folder named ``s3:``."""
    out = getattr(args, "out", None)
    if isinstance(out, str):  # (also: ``s3:/b/x``, a URL that lost its '//', in every command)
        from kubric.io.output_check import check_output
        check_output(out, urls=args.command in URL_OUTPUTS, command=f"kubric {args.command}")


def _terminated(signum, _frame):
    """SIGTERM (``kill``, Slurm): unwind like Ctrl-C, so ``finally`` blocks remove temporary
    files; exit status 128 + 15 (docs/exit-codes.md)."""
    raise SystemExit(128 + signum)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    debug = args.debug or os.environ.get("KUBRIC_DEBUG", "") not in ("", "0")
    if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        signal.signal(signal.SIGTERM, _terminated)  # unwind: every command's cleanup runs
    try:
        check_local_output(args)
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"kubric {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as err:
        code = exit_code(err)
        if code is None:
            raise
        if debug:
            traceback.print_exc()
        print(f"kubric {args.command}: error: {error_line(err)}", file=sys.stderr)
        return code


if __name__ == "__main__":
    sys.exit(main())
