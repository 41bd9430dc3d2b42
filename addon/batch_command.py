"""``blender -b --command cable_recon reconstruct IMAGES -o out.blend [options]``, and
``blender -b --command cable_recon batch SEQUENCES -o OUT_DIR [options]``: every sequence of a
folder into a .blend of its own.

Registered with ``bpy.utils.register_cli_command``; the same handler runs with the bpy module
from Python (``handle_command(["reconstruct", ...])``). Exit codes are the engine's: 0
success, 2 bad input, 3 reconstruction failed, 130 cancelled.

A batch reconstructs the sequences as the engine's ``batch`` does (:mod:`engine.batch`:
several side by side, each in a process of its own, resumable), then builds each result's
.blend here, one after the other, each from the file Blender started with (the startup file
if none) as a ``reconstruct`` command would: the open file is reloaded for each, so with the
bpy module, unsaved changes to it are lost.
"""

import argparse
import sys
from pathlib import Path

import bpy

from ..engine.batch import batch_exit_code, run_batch, sequence_outputs, summary_table
from ..engine.cli.main import (BATCH_USAGE, EXIT_BAD_INPUT, RECONSTRUCT_USAGE, ProgressBar,
                               add_batch_arguments, add_reconstruct_arguments, batch_arguments,
                               reconstruct_arguments, run_with_exit_code)
from ..engine.cli.settings import add_settings_arguments, settings_from_arguments
from ..engine.errors import InputError, OutputError
from ..engine.io.files import check_output_file
from ..engine.io.result import read_result
from ..engine.progress import StageProgress
from ..engine.stages.bezier import BezierSettings
from .reconstruction import (RunRequest, apply_outcome, outcome_of_result, reconstruct_work,
                             sequence_name)

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
    _add_blend_arguments(rebuild)
    batch = commands.add_parser(
        "batch", help="a folder of sequences to a .blend each",
        usage=f"%(prog)s SEQUENCES [--no-cameras] {BATCH_USAGE}",
        description="Every sequence of a folder to OUT_DIR/<name>.blend (beside the engine's "
                    "<name>.cable.json, <name>.log and summary.json), several reconstructed "
                    "side by side; run it again to go on where it stopped.")
    add_batch_arguments(batch)
    _add_blend_arguments(batch)
    return parser


def _add_blend_arguments(parser):
    parser.add_argument("--no-cameras", action="store_true",
                        help="leave the cameras out of the .blend")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--debug", action="store_true",
                        help="an internal error shows its traceback (and is not caught)")
    add_settings_arguments(parser, BezierSettings, prefix="curve", aliases=True)


def _save(output):
    try:
        bpy.ops.wm.save_as_mainfile(filepath=str(output), check_existing=False, copy=True)
    except RuntimeError as error:  # a full disk: Blender's report, first line
        raise OutputError(f"cannot write {output}: {str(error).strip().splitlines()[0]}") \
            from None


def _reconstruct(args):
    output = Path(args.output).resolve()
    if output.suffix != ".blend":
        raise InputError(f"{args.output}: the output must be a .blend file")
    check_output_file(output, overwrite=args.overwrite)  # before the work, not when saved
    engine = reconstruct_arguments(args)
    images = str(Path(engine["images"]).resolve())
    # absolute: a flip after the .blend is reopened re-runs from these, wherever Blender runs
    cameras, masks = (str(Path(engine[key]).resolve()) if engine[key] else None
                      for key in ("cameras", "masks"))
    request = RunRequest(
        images=images, name=sequence_name(images), cameras=cameras,
        masks=masks, hsv=str(engine["colour"]) if engine["colour"] else None,
        diameter=engine["diameter"], length=engine["length"], settings=engine["settings"],
        curve=settings_from_arguments(BezierSettings, args, prefix="curve"),
        with_cameras=not args.no_cameras)
    progress = (lambda fraction, message: None) if args.quiet else ProgressBar()
    outcome = reconstruct_work(request)(progress, None)
    obj = apply_outcome(bpy.context, request, outcome)
    _save(output)
    result = outcome.state.result
    for warning in outcome.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    print(f"{obj.name}: {len(result.paths)} path(s), {len(result.crossings)} crossing(s), "
          f"{outcome.report['control_points']} control points -> {output}", file=sys.stderr)


def _batch(args):
    arguments = batch_arguments(args)
    output = Path(arguments["output"]).resolve()
    progress = StageProgress((lambda fraction, message: None) if args.quiet else ProgressBar())
    outcomes = run_batch(**arguments, progress=progress.part(0.0, 0.9))
    curve = settings_from_arguments(BezierSettings, args, prefix="curve")
    inputs = arguments["inputs"]
    made = [(s, o) for s, o in zip(arguments["sequences"], outcomes)
            if o.status in ("done", "skipped")]
    kept, started_with = [], bpy.data.filepath
    for number, (sequence, outcome) in enumerate(made):
        blend = output / f"{sequence.name}.blend"
        progress.part(0.9, 1.0)(number / len(made), f"{blend.name}")
        if blend.exists() and not args.overwrite:
            kept.append(blend.name)
            continue
        images = str(sequence.images.resolve())
        folder = sequence.folder.resolve()
        request = RunRequest(
            images=images, name=sequence_name(images),
            cameras=str(folder / args.cameras) if args.cameras else None,
            masks=str(folder / args.masks) if args.masks else None, hsv=inputs.hsv,
            diameter=inputs.diameter, length=inputs.length, settings=arguments["settings"],
            curve=curve, with_cameras=not args.no_cameras)
        result = read_result(sequence_outputs(sequence, output)[0])
        if started_with:  # each .blend starts as a reconstruct command's would
            bpy.ops.wm.open_mainfile(filepath=started_with)
        else:
            bpy.ops.wm.read_homefile()
        apply_outcome(bpy.context, request, outcome_of_result(result, request))
        _save(blend)
    progress(1.0, "done")
    print(summary_table(outcomes), file=sys.stderr)
    if kept:
        print(f"kept (--overwrite replaces them): {', '.join(kept)}", file=sys.stderr)
    print(f"{len(made) - len(kept)} .blend file(s) written to {output}", file=sys.stderr)
    return batch_exit_code(outcomes)


def handle_command(argv):
    """The ``--command`` handler: returns the process's exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # argparse printed the usage and the reason
        return exit_.code if isinstance(exit_.code, int) else EXIT_BAD_INPUT
    run = _batch if args.command == "batch" else _reconstruct
    return run_with_exit_code(run, args, debug=args.debug)
