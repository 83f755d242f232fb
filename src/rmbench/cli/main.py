"""The ``rmbench`` command line: argument parsing only; the work is in the library. Each
module here registers its subcommands (``add_parsers``) and holds what they print."""

from __future__ import annotations

import argparse
import logging
import sys

from rmbench.cli import dataset, evaluate, experts, train
from rmbench.tasks.registry import UnknownTaskError


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="rmbench", description="RMBench: memory-dependent "
                                     "dual-arm manipulation on MuJoCo")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in (experts, dataset, train, evaluate):
        module.add_parsers(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)  # as given, for the records
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    episodes = getattr(args, "episodes", None)
    if episodes is not None and episodes < 1:
        print("rmbench: error: --episodes must be at least 1", file=sys.stderr)
        return 2
    try:
        return args.func(args)
    except (UnknownTaskError, ValueError, RuntimeError) as err:
        print(f"rmbench: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # a path that is a file, a port in use, a server that is not there
        print(f"rmbench: error: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("rmbench: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
