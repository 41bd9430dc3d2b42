"""The ``python -m engine`` command line.

Exit codes: 0 success, 2 bad input (one-line reason on stderr), 3 reconstruction failed.
"""

import argparse
import logging
import sys

from . import __version__
from .errors import InputError, ReconstructionError

__all__ = ["main", "build_parser"]

EXIT_OK, EXIT_BAD_INPUT, EXIT_FAILED = 0, 2, 3
log = logging.getLogger(__name__)


def build_parser():
    """The argument parser; subcommands are added by the stages as they exist."""
    parser = argparse.ArgumentParser(
        prog="python -m engine",
        description="Reconstruct a cable, rope or hose from photos as one continuous curve.",
    )
    parser.add_argument("--version", action="version", version=f"cable_recon {__version__}")
    parser.add_argument("-q", "--quiet", action="store_true", help="only print errors")
    parser.add_subparsers(dest="command", metavar="COMMAND")
    return parser


def main(argv=None):
    """Run the command line; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    package_log = logging.getLogger(__package__)
    package_log.addHandler(handler)
    package_log.setLevel(logging.ERROR if args.quiet else logging.INFO)
    if getattr(args, "run", None) is None:
        parser.print_help(sys.stderr)
        return EXIT_BAD_INPUT
    try:
        return args.run(args) or EXIT_OK
    except InputError as error:
        print(f"error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except ReconstructionError as error:
        print(f"reconstruction failed: {error}", file=sys.stderr)
        return EXIT_FAILED
    except FileExistsError as error:
        print(f"error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    finally:
        package_log.removeHandler(handler)
