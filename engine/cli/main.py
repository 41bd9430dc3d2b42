"""The ``python -m engine`` command line.

Exit codes: 0 success, 2 bad input (one-line reason on stderr), 3 reconstruction failed,
4 an internal error (a bug: one line naming where, the traceback in a file), 130 cancelled.
"""

import argparse
import importlib
import importlib.util
import logging
import os
import signal
import sys
import tempfile
import threading
import traceback
from pathlib import Path

from .. import __version__
from ..batch import STOP_ON_SIGINT
from ..errors import Cancelled, InputError, ReconstructionError
from .settings import (PIPELINE_GROUPS, add_pipeline_arguments, checked_type,
                       pipeline_from_arguments)

__all__ = ["main", "build_parser", "add_reconstruct_arguments", "reconstruct_arguments",
           "add_batch_arguments", "batch_arguments", "run_with_exit_code", "ProgressBar",
           "RECONSTRUCT_USAGE", "BATCH_USAGE"]

EXIT_OK, EXIT_BAD_INPUT, EXIT_FAILED, EXIT_BUG = 0, 2, 3, 4
log = logging.getLogger(__name__)


class ProgressBar:
    """``progress(fraction, message)`` drawn as one line on stderr (redrawn on a terminal)."""

    def __init__(self, stream=sys.stderr, width=30):
        self.stream, self.width = stream, width
        self.live = stream.isatty()
        self.last = None

    def __call__(self, fraction, message):
        filled = int(round(self.width * min(max(fraction, 0.0), 1.0)))
        line = f"[{'#' * filled}{'.' * (self.width - filled)}] {100 * fraction:3.0f}% {message}"
        if self.live:
            self.stream.write("\r" + line[:120].ljust(120))
            if fraction >= 1.0:
                self.stream.write("\n")
        elif line != self.last:
            self.stream.write(line + "\n")
        self.stream.flush()
        self.last = line


def _add_run_arguments(parser, groups):
    """The settings flags of ``groups`` (each with its prefix), ``--no-agreement``,
    ``--reference-frame``, ``--workers`` and ``--settings``."""
    from dataclasses import fields

    from ..pipeline import PipelineSettings

    own = {field.name: field for field in fields(PipelineSettings)}
    frame, workers = own["reference_frame"], own["workers"]
    parser.add_argument("--settings", metavar="RUN_JSON",
                        help="start from the settings (and the colour and scale) of an earlier "
                             "run: its result file, or a run file saved in Blender; the flags "
                             "given here change them")
    parser.add_argument("--reference-frame", type=checked_type(frame, "--reference-frame"),
                        default=argparse.SUPPRESS,
                        help=f"frame the automatic colour is taken from (default {frame.default})")
    parser.add_argument("--workers", type=checked_type(workers, "--workers"),
                        default=argparse.SUPPRESS,
                        help="threads for the work done frame by frame and view by view, and "
                             "for the masks beside the camera estimation (default 0: one per "
                             "CPU, at most 4; the result is the same on any number)")
    if "agreement" in groups:
        parser.add_argument("--no-agreement", action="store_true",
                            help="use each frame's mask as segmented, not checked against the "
                                 "other views (masks given with --masks always are)")
    add_pipeline_arguments(parser, groups)


def _run_settings(args, groups):
    """The run's :class:`PipelineSettings` and inputs: those of ``--settings`` (or the
    defaults), with the flags given."""
    from dataclasses import replace

    from ..pipeline import RunInputs, read_run

    base, inputs = (None, RunInputs()) if args.settings is None else read_run(args.settings)
    settings = pipeline_from_arguments(args, base, groups)
    if getattr(args, "no_agreement", False):
        settings = replace(settings, agreement=replace(settings.agreement, rounds=0))
    return settings, inputs


_SEGMENT_GROUPS = ("segmentation", "cameras", "agreement", "carving", "upright")


def _run_segment(args):
    from ..stages.segmentation import ColourRange
    from .segment import segment_sequence_to_folder

    settings, inputs = _run_settings(args, _SEGMENT_GROUPS)
    hsv = args.hsv or (None if args.auto else inputs.hsv)
    colour, widths = segment_sequence_to_folder(
        args.images, args.output, colour=ColourRange.parse(hsv) if hsv else None,
        settings=settings, overwrite=args.overwrite, cameras=args.cameras,
        progress=None if args.quiet else ProgressBar())
    several = settings.segmentation.all_cables and hsv is None  # each cable's colour was logged
    log.info("%d frames, cable %.1f-%.1f px wide%s", len(widths), min(widths), max(widths),
             ", every cable of its own colour" if several else f", --hsv {colour}")


_CAMERA_GROUPS = ("cameras", "upright")


def _run_cameras(args):
    from .cameras import cameras_command

    settings = pipeline_from_arguments(args, groups=_CAMERA_GROUPS)
    estimate = cameras_command(args.images, args.output, overwrite=args.overwrite,
                               settings=settings.cameras, upright=settings.upright,
                               progress=None if args.quiet else ProgressBar())
    if estimate.unregistered:
        log.warning("did not register: %s", ", ".join(estimate.unregistered))
    log.info("%d cameras written to %s", len(estimate.cameras), args.output)


#: The usage line of the options every run takes (the settings flags are too many to list).
_RUN_USAGE = ("[--diameter MM | --length M] [--hsv H1,S1,V1,H2,S2,V2] [--overwrite] "
              "[--settings RUN_JSON] [SETTINGS ...]")
#: The usage line of a reconstruction's options.
RECONSTRUCT_USAGE = f"[--cameras MODEL_DIR] [--masks MASKS_DIR] {_RUN_USAGE}"
#: The usage line of a batch's options.
BATCH_USAGE = f"[-o OUT_DIR] [--jobs N] [--cameras NAME] [--masks NAME] {_RUN_USAGE}"


def add_reconstruct_arguments(parser):
    """The inputs and options of a reconstruction, shared by ``reconstruct`` and the add-on's
    ``blender --command`` entry (read back with :func:`reconstruct_arguments`)."""
    parser.add_argument("images", help="folder of .jpg/.png frames, or a video")
    parser.add_argument("--cameras", metavar="MODEL_DIR",
                        help="COLMAP model (text or binary) of the frames, used as is "
                             "(default: estimate the cameras)")
    parser.add_argument("--masks", metavar="MASKS_DIR",
                        help="masks written by 'segment' (possibly edited), used instead of "
                             "segmenting")
    _add_common_arguments(parser)


def add_batch_arguments(parser):
    """The inputs and options of a batch (``batch`` and the add-on's ``batch`` command; read
    back with :func:`batch_arguments`): a folder of sequences instead of one, each given the
    same settings; ``--cameras`` and ``--masks`` name a folder inside each sequence's."""
    parser.add_argument("sequences", help="folder of sequences: folders of .jpg/.png frames "
                                          "(or each with an images/ folder of them), or videos")
    parser.add_argument("-o", "--output", metavar="OUT_DIR",
                        help="output folder (default: <sequences folder name>.results here)")
    parser.add_argument("--jobs", type=int, metavar="N",
                        help="sequences reconstructed side by side (default: the machine's "
                             "cores)")
    parser.add_argument("--cameras", metavar="NAME",
                        help="the COLMAP model of each sequence, a folder of that name inside "
                             "it, e.g. sparse (default: estimate the cameras)")
    parser.add_argument("--masks", metavar="NAME",
                        help="the masks of each sequence, a folder of that name inside it")
    _add_common_arguments(parser)


def _add_common_arguments(parser):
    scale = parser.add_mutually_exclusive_group()
    scale.add_argument("--diameter", type=float, metavar="MM",
                       help="the cable's measured diameter in mm: the result is in metres")
    scale.add_argument("--length", type=float, metavar="M",
                       help="the cable's length in metres: the result is in metres")
    parser.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    parser.add_argument("--hsv", metavar="H1,S1,V1,H2,S2,V2",
                        help="cable colour range (default: found on the reference frame)")
    _add_run_arguments(parser, PIPELINE_GROUPS)


def _settings_and_inputs(args):
    """The run's settings and its colour and scale: the flags given, else what a run read
    with ``--settings`` gives."""
    from ..pipeline import RunInputs

    settings, inputs = _run_settings(args, PIPELINE_GROUPS)
    hsv = args.hsv or inputs.hsv
    if hsv:
        from ..stages.colour_range import ColourRange

        hsv = str(ColourRange.parse(hsv))
    diameter, length = args.diameter, args.length
    if diameter is None and length is None:
        diameter, length = inputs.diameter, inputs.length
    return settings, RunInputs(hsv=hsv, diameter=diameter, length=length)


def reconstruct_arguments(args):
    """Keyword arguments of :func:`engine.pipeline.run_reconstruction` from parsed arguments
    (a run read with ``--settings`` gives the colour and scale the command line does not)."""
    from ..stages.segmentation import ColourRange

    settings, inputs = _settings_and_inputs(args)
    return dict(images=args.images, cameras=args.cameras, masks=args.masks,
                colour=ColourRange.parse(inputs.hsv) if inputs.hsv else None,
                diameter=inputs.diameter, length=inputs.length, settings=settings)


def batch_arguments(args):
    """Keyword arguments of :func:`engine.batch.run_batch` (but ``progress`` and ``cancel``)
    from parsed arguments."""
    from ..batch import find_sequences

    if args.jobs is not None and args.jobs < 1:
        raise InputError("--jobs must be 1 or more")
    settings, inputs = _settings_and_inputs(args)
    sequences = find_sequences(args.sequences)
    output = args.output or Path(args.sequences).resolve().name + ".results"
    return dict(sequences=sequences, output=output, settings=settings, inputs=inputs,
                cameras=args.cameras, masks=args.masks, jobs=args.jobs,
                overwrite=args.overwrite)


def _run_reconstruct(args):
    from pathlib import Path

    from ..io.files import check_output_file
    from ..io.obj import write_obj
    from ..io.result import write_result
    from ..pipeline import reconstruct

    output = Path(args.output or Path(args.images).resolve().name + ".cable.json")
    for path in (output, Path(args.obj) if args.obj else None):
        if path is not None:  # before the work, not when its result is written
            check_output_file(path, overwrite=args.overwrite)
    result = reconstruct(**reconstruct_arguments(args),
                         progress=None if args.quiet else ProgressBar())
    write_result(result, output, overwrite=args.overwrite)
    if args.obj:
        write_obj(result, args.obj, overwrite=args.overwrite)
    for warning in result.warnings:
        log.warning("warning: %s", warning)
    points = sum(len(path.points) for path in result.paths)
    log.info("%d path(s), %d points, %d crossing(s), radius %.4g %s -> %s", len(result.paths),
             points, len(result.crossings), result.radius, result.units, output)


def build_parser():
    """The argument parser with every stage command."""
    parser = argparse.ArgumentParser(
        prog="python -m engine",
        description="Reconstruct a cable, rope or hose from photos as one continuous curve.",
    )
    parser.add_argument("--version", action="version", version=f"cable_recon {__version__}")
    parser.add_argument("-q", "--quiet", action="store_true", help="only print errors")
    parser.add_argument("--debug", action="store_true",
                        help="an internal error shows its traceback (and is not caught)")
    # -q also after the command (a subcommand's default must not undo a -q given before it).
    quiet = argparse.ArgumentParser(add_help=False)
    quiet.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                       help="only print errors")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    for add in (_add_segment_command, _add_cameras_command, _add_reconstruct_command,
                _add_batch_command):
        add(commands, quiet)
    bench = _developer_bench()
    if bench is not None:  # a developer checkout: the extension leaves engine.bench out
        bench.add_bench_command(commands, parents=[quiet])
    return parser


def _add_segment_command(commands, quiet):
    """``segment IMAGES -o OUT``: the masks, junction maps and a contact sheet."""
    segment = commands.add_parser(
        "segment", parents=[quiet], help="write cable masks and junction maps of every frame",
        usage="%(prog)s IMAGES -o OUT [--hsv H1,S1,V1,H2,S2,V2 | --auto] [--cameras MODEL_DIR] "
              "[--overwrite] [--settings RUN_JSON] [SETTINGS ...]",
        description="Segment the cable in every frame and check each mask against the other "
                    "views (cameras from --cameras, or estimated): OUT/masks/*.png (cable = "
                    "255), OUT/junctions/*.png and OUT/contact_sheet.png for a quick look "
                    "(red: removed, cyan: filled by the agreement across views).")
    segment.add_argument("images", help="folder of .jpg/.png frames, or a video")
    segment.add_argument("-o", "--output", required=True, help="output folder")
    colour = segment.add_mutually_exclusive_group()
    colour.add_argument("--hsv", metavar="H1,S1,V1,H2,S2,V2",
                        help="cable colour range (OpenCV HSV: H 0-179 wrapping, S and V 0-255)")
    colour.add_argument("--auto", action="store_true",
                        help="find the cable colour on the reference frame (the default)")
    segment.add_argument("--overwrite", action="store_true", help="replace existing masks")
    segment.add_argument("--cameras", metavar="MODEL_DIR",
                         help="COLMAP model (text or binary) of the frames, to agree the masks "
                              "across views (default: estimate the cameras)")
    _add_run_arguments(segment, _SEGMENT_GROUPS)
    segment.set_defaults(run=_run_segment)


def _add_cameras_command(commands, quiet):
    """``cameras IMAGES -o MODEL_DIR``: a COLMAP model of the frames."""
    cameras = commands.add_parser(
        "cameras", parents=[quiet],
        help="estimate the cameras with structure from motion (pycolmap)",
        description="Estimate the cameras of the frames and write a COLMAP text model "
                    "(image names = file names), upright: the table is z = 0.")
    cameras.add_argument("images", help="folder of .jpg/.png frames, or a video")
    cameras.add_argument("-o", "--output", required=True, help="model folder")
    cameras.add_argument("--overwrite", action="store_true", help="replace an existing model")
    add_pipeline_arguments(cameras, _CAMERA_GROUPS, aliases=())
    cameras.set_defaults(run=_run_cameras)


def _add_reconstruct_command(commands, quiet):
    """``reconstruct IMAGES``: the result JSON (and an OBJ)."""
    rebuild = commands.add_parser(
        "reconstruct", parents=[quiet], help="reconstruct the cable as one continuous centreline",
        usage=f"%(prog)s IMAGES [-o RESULT_JSON] [--obj OBJ] {RECONSTRUCT_USAGE}",
        description="Reconstruct the cable(s) in the frames: a result JSON "
                    "(cable_recon.result/1) with one path per cable, its crossings and cameras; "
                    "every settings group's fields are flags with the group's name as prefix "
                    "(segmentation and carving ones also without it).")
    add_reconstruct_arguments(rebuild)
    rebuild.add_argument("-o", "--output", metavar="RESULT_JSON",
                         help="result file (default: <images folder name>.cable.json here)")
    rebuild.add_argument("--obj", metavar="OBJ", help="also write the cable as an OBJ tube mesh")
    rebuild.set_defaults(run=_run_reconstruct)


def _add_batch_command(commands, quiet):
    """``batch SEQUENCES``: one result per sequence and a summary."""
    batch = commands.add_parser(
        "batch", parents=[quiet], help="reconstruct every sequence in a folder",
        usage=f"%(prog)s SEQUENCES [--obj] {BATCH_USAGE}",
        description="Reconstruct every sequence in a folder, each as 'reconstruct' would and "
                    "with the same settings, several side by side: OUT_DIR/<name>.cable.json "
                    "(and .obj), <name>.log and summary.json. Run it again to go on: "
                    "sequences with a result made with the same settings are skipped, failed "
                    "ones are tried again. Exit code 0 when every sequence has its result, "
                    "else the highest of the failed ones' (2, 3, 4), 130 if cancelled.")
    add_batch_arguments(batch)
    batch.add_argument("--obj", action="store_true",
                       help="also write each cable as an OBJ tube mesh")
    batch.set_defaults(run=_run_batch)


def _run_batch(args):
    from ..batch import batch_exit_code, run_batch, summary_table

    arguments = batch_arguments(args)
    log.info("%d sequence(s) -> %s", len(arguments["sequences"]), arguments["output"])
    outcomes = run_batch(**arguments, obj=args.obj,
                         progress=None if args.quiet else ProgressBar())
    log.info("%s", summary_table(outcomes))
    if args.quiet:  # the table is not printed: the failures are errors
        for outcome in outcomes:
            if outcome.status == "failed":
                log.error("%s: %s", outcome.name, outcome.reason)
    return batch_exit_code(outcomes)


def _developer_bench():
    """``engine.bench.cli`` where the developer packages are present (a checkout), else None:
    the extension ships without them, and its command line has no ``bench``."""
    package = __package__.rpartition(".")[0]
    if importlib.util.find_spec(f"{package}.bench") is None:
        return None
    return importlib.import_module(f"{package}.bench.cli")


def main(argv=None):
    """Run the command line; returns the exit code."""
    _stop_on_sigint()
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
        return run_with_exit_code(args.run, args, debug=args.debug)
    finally:
        package_log.removeHandler(handler)


def _stop_on_sigint():
    """A run a batch started stops on SIGINT, as a cancel asks, even if it inherited an
    ignored one (Python then never raises KeyboardInterrupt): the default handler back."""
    if (os.environ.get(STOP_ON_SIGINT) == "1" and threading.current_thread() is
            threading.main_thread() and signal.getsignal(signal.SIGINT) is signal.SIG_IGN):
        signal.signal(signal.SIGINT, signal.default_int_handler)


def run_with_exit_code(run, *args, stream=None, debug=False):
    """Call ``run(*args)``; the exit code, with a one-line reason on ``stream`` on failure.

    0 success (or what ``run`` returns), 2 bad input, 3 reconstruction failed, 4 an internal
    error (a bug: the line names the engine's module, function and line it came from and the
    file its traceback went to; re-raised when ``debug``), 130 cancelled.
    """
    stream = stream or sys.stderr
    try:
        return run(*args) or EXIT_OK
    except InputError as error:
        print(f"error: {error}", file=stream)
        return EXIT_BAD_INPUT
    except ReconstructionError as error:
        print(f"reconstruction failed: {error}", file=stream)
        return EXIT_FAILED
    except FileExistsError as error:
        print(f"error: {error}", file=stream)
        return EXIT_BAD_INPUT
    except (Cancelled, KeyboardInterrupt):
        print("cancelled", file=stream)
        return 130
    except Exception as error:
        if debug:
            raise
        path = Path(tempfile.gettempdir()) / f"cable_recon-traceback-{os.getpid()}.txt"
        try:
            path.write_text("".join(traceback.format_exception(error)))
            kept = f"the traceback is in {path}"
        except OSError:
            kept = "run with --debug to see the traceback"
        message = str(error).splitlines()[0] if str(error) else ""
        print(f"internal error (a bug, please report it) in {_where(error)}: "
              f"{type(error).__name__}: {message} ({kept})", file=stream)
        return EXIT_BUG


def _where(error):
    """``module.function:line`` of the deepest frame of the engine (or the add-on) in the
    traceback, else of the deepest frame."""
    frames = traceback.extract_tb(error.__traceback__)
    root = Path(__file__).resolve().parents[2]
    ours = [frame for frame in frames
            if any(Path(frame.filename).resolve().is_relative_to(root / package)
                   for package in ("engine", "addon"))]
    frame = (ours or frames)[-1]
    path = Path(frame.filename).resolve()
    name = ".".join(path.relative_to(root).with_suffix("").parts) if ours else path.stem
    return f"{name}.{frame.name}:{frame.lineno}"
