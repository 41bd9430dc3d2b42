"""``blender -b --command cable_recon reconstruct IMAGES -o out.blend [options]``.

Registered with ``bpy.utils.register_cli_command``; the same handler runs with the bpy module
from Python (``handle_command(["reconstruct", ...])``). Exit codes are the engine's: 0
success, 2 bad input, 3 reconstruction failed, 130 cancelled.
"""

import argparse
import sys
from pathlib import Path

import bpy

from ..engine.cli.main import (EXIT_BAD_INPUT, RECONSTRUCT_USAGE, ProgressBar,
                               add_reconstruct_arguments, reconstruct_arguments,
                               run_with_exit_code)
from ..engine.cli.settings import add_settings_arguments, settings_from_arguments
from ..engine.errors import InputError, OutputError
from ..engine.io.files import check_output_file
from ..engine.stages.bezier import BezierSettings
from .reconstruction import RunRequest, apply_outcome, reconstruct_work, sequence_name

__all__ = ["COMMAND", "handle_command", "build_parser"]

COMMAND = "cable_recon"


def build_parser():
    """The batch command's arguments (the engine's reconstruct options, plus the .blend)."""
    parser = argparse.ArgumentParser(
        prog=f"blender -b --command {COMMAND}",
        description="Reconstruct a cable from photos into a .blend: a bevelled Bézier curve "
                    "(and the cameras) in a collection named after the images' folder.")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    rebuild = commands.add_parser("reconstruct", help="images to a .blend",
                                  usage=f"%(prog)s IMAGES -o BLEND [--no-cameras] "
                                        f"{RECONSTRUCT_USAGE}",
                                  description="Images to a .blend with the cable's curve.")
    add_reconstruct_arguments(rebuild)
    rebuild.add_argument("-o", "--output", required=True, metavar="BLEND",
                         help="the .blend to write (never replaced without --overwrite)")
    rebuild.add_argument("--no-cameras", action="store_true",
                         help="leave the cameras out of the .blend")
    rebuild.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    rebuild.add_argument("--debug", action="store_true",
                         help="an internal error shows its traceback (and is not caught)")
    add_settings_arguments(rebuild, BezierSettings, prefix="curve", aliases=True)
    return parser


def _reconstruct(args):
    output = Path(args.output).resolve()
    if output.suffix != ".blend":
        raise InputError(f"{args.output}: the output must be a .blend file")
    check_output_file(output, overwrite=args.overwrite)  # before the work, not when saved
    engine = reconstruct_arguments(args)
    images = str(Path(engine["images"]).resolve())
    request = RunRequest(
        images=images, name=sequence_name(images), cameras=engine["cameras"],
        masks=engine["masks"], hsv=str(engine["colour"]) if engine["colour"] else None,
        diameter=engine["diameter"], length=engine["length"], settings=engine["settings"],
        curve=settings_from_arguments(BezierSettings, args, prefix="curve"),
        with_cameras=not args.no_cameras)
    progress = (lambda fraction, message: None) if args.quiet else ProgressBar()
    outcome = reconstruct_work(request)(progress, None)
    obj = apply_outcome(bpy.context, request, outcome)
    try:
        bpy.ops.wm.save_as_mainfile(filepath=str(output), check_existing=False, copy=True)
    except RuntimeError as error:  # a full disk: Blender's report, first line
        raise OutputError(f"cannot write {output}: {str(error).strip().splitlines()[0]}") \
            from None
    result = outcome.state.result
    for warning in outcome.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    print(f"{obj.name}: {len(result.paths)} path(s), {len(result.crossings)} crossing(s), "
          f"{outcome.report['control_points']} control points -> {output}", file=sys.stderr)


def handle_command(argv):
    """The ``--command`` handler: returns the process's exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # argparse printed the usage and the reason
        return exit_.code if isinstance(exit_.code, int) else EXIT_BAD_INPUT
    return run_with_exit_code(_reconstruct, args, debug=args.debug)
