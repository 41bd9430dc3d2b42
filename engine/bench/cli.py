"""``python -m engine bench STAGE``: the benchmarks' command (developer checkouts only)."""

from ..cli.main import ProgressBar
from ..cli.settings import add_pipeline_arguments, settings_from_arguments
from ..errors import InputError

__all__ = ["STAGES", "add_bench_command", "run_bench"]

STAGES = ("segment", "looks", "cameras", "carve", "rod", "pipeline", "pipeline-looks", "topology",
          "faults", "preview", "curve", "cancel", "memory", "batch", "scaling", "speed")


def add_bench_command(commands, *, parents=()):
    """Add ``bench`` to the command line's subparsers ``commands``."""
    bench = commands.add_parser(
        "bench", parents=list(parents),
        help="measure a stage's accuracy and speed on ground-truth scenes",
        description="Print a table: one row per ground-truth scene.")
    bench.add_argument("stage", choices=STAGES)
    bench.add_argument("--views", type=int, default=30, help="views per synthetic scene")
    bench.add_argument("--seeds", type=int, default=3,
                       help="scenes per family and seed set (looks, pipeline-looks, "
                            "topology, pipeline), per family (segment, carve), in all "
                            "(cameras, rod) or the sequences (batch)")
    bench.add_argument("--families", metavar="NAMES",
                       help="comma-separated families: look families (looks, pipeline-looks: "
                            "those only, without the Cycles captures and real photos) or "
                            "easy, hard (topology: those only, without the Cycles captures)")
    bench.add_argument("--sample", default="samples/sequence",
                       help="the realistic sample's folder (skipped if missing)")
    bench.add_argument("--profile", action="store_true",
                       help="pipeline: run each reconstruction under cProfile and print the "
                            "functions that took its time after the table")
    bench.add_argument("--per-scene", action="store_true",
                       help="looks: one row per scene and capture, not per family (two runs' "
                            "tables then compare scene by scene)")
    bench.add_argument("--ours-only", action="store_true",
                       help="pipeline-looks: only the rows of our masks (not the naive "
                            "threshold's or the exact masks', which no setting changes)")
    # the masks' settings, as `reconstruct` takes them (segment, looks, pipeline-looks)
    add_pipeline_arguments(bench, groups=("segmentation",), aliases=())
    bench.set_defaults(run=run_bench)


def _chosen_families(args, known, kind):
    """The families ``--families`` names, each one of ``known`` (an InputError otherwise)."""
    families = tuple(name.strip() for name in args.families.split(",") if name.strip())
    unknown = [name for name in families if name not in known]
    if unknown or not families:
        raise InputError(f"unknown {kind} famil{'ies' if len(unknown) > 1 else 'y'} "
                         f"{', '.join(unknown) or '(none given)'}: choose from "
                         f"{', '.join(known)}")
    return families


def _family_options(args):
    """``bench looks`` / ``pipeline-looks`` options of ``--families``: those families only,
    without the captures and real photos."""
    if args.families is None:
        return {}
    from ..synthetic.looks import LOOK_FAMILIES

    options = {"families": _chosen_families(args, LOOK_FAMILIES, "look"), "captures": None}
    return {**options, "real": None} if args.stage == "looks" else options


def _topology_families(args):
    """``bench topology``'s ``--families``: easy, hard or both, without the Cycles captures."""
    if args.families is None:
        return {}
    from .topology import TOPOLOGY_FAMILIES

    return {"families": _chosen_families(args, TOPOLOGY_FAMILIES, "topology"), "captures": None}


def run_bench(args):
    """Print the table(s) of ``bench STAGE``."""
    from ..stages.segmentation import SegmentationSettings
    from .common import format_table
    from .segment import bench_segment

    segmentation = settings_from_arguments(SegmentationSettings, args, prefix="segmentation")
    if args.stage in ("segment", "looks"):
        from .looks import bench_looks

        if args.stage == "segment":
            print(format_table(bench_segment(sample=args.sample, views=args.views,
                                             seeds=args.seeds, settings=segmentation)))
            print()
        rows = bench_looks(seeds=args.seeds, settings=segmentation,
                           per_scene=args.per_scene and args.stage == "looks",
                           **_family_options(args))
    elif args.stage == "cameras":
        from .cameras import bench_cameras

        rows = bench_cameras(views=args.views, seeds=tuple(range(args.seeds)),
                             include_sample=True)
    elif args.stage == "carve":
        from .carve import bench_carve

        rows = bench_carve(views=args.views, seeds=tuple(range(1, args.seeds + 1)))
    elif args.stage == "rod":
        from .rod import bench_rod

        rows = bench_rod(seeds=tuple(range(args.seeds)))
    elif args.stage in ("preview", "curve", "cancel"):
        from . import interactive

        bench = getattr(interactive, f"bench_{args.stage}")
        rows = bench(sample=args.sample, **({"views": args.views} if args.stage == "curve"
                                             else {}))
    elif args.stage == "memory":
        from .memory import MEMORY_COLUMNS, bench_memory

        rows = bench_memory(progress=None if args.quiet else ProgressBar())
        print(format_table(rows, MEMORY_COLUMNS))
        return
    elif args.stage == "scaling":
        from .scaling import SCALING_COLUMNS, bench_scaling

        rows = bench_scaling(progress=None if args.quiet else ProgressBar())
        print(format_table(rows, SCALING_COLUMNS))
        return
    elif args.stage == "speed":
        from .speed import SPEED_COLUMNS, bench_speed

        rows = bench_speed(views=args.views, sample=args.sample,
                           progress=None if args.quiet else ProgressBar())
        print(format_table(rows, SPEED_COLUMNS))
        return
    elif args.stage == "batch":
        from .batch import bench_batch

        rows = bench_batch(sequences=args.seeds, views=args.views,
                           progress=None if args.quiet else ProgressBar())
    elif args.stage == "faults":
        from .faults import bench_faults

        rows = bench_faults(progress=None if args.quiet else ProgressBar())
    elif args.stage == "topology":
        from .topology import SCENE_COLUMNS, SUMMARY_COLUMNS, bench_topology

        summary, scenes = bench_topology(seeds=args.seeds, views=args.views,
                                         progress=None if args.quiet else ProgressBar(),
                                         **_topology_families(args))
        print(format_table(summary, SUMMARY_COLUMNS))
        print()
        print(format_table(scenes, SCENE_COLUMNS))
        return
    elif args.stage == "pipeline-looks":
        from .pipeline import MASK_ROWS, bench_pipeline_looks

        given = segmentation if segmentation != SegmentationSettings() else None
        rows = bench_pipeline_looks(seeds=args.seeds, segmentation=given,
                                    masks=MASK_ROWS[:1] if args.ours_only else MASK_ROWS,
                                    progress=None if args.quiet else ProgressBar(),
                                    **_family_options(args))
    else:
        from .pipeline import bench_pipeline
        from .profile import PROFILE_COLUMNS

        rows = bench_pipeline(views=args.views, sample=args.sample, seeds=args.seeds,
                              progress=None if args.quiet else ProgressBar(),
                              profile=args.profile)
        if args.profile:
            rows, functions = rows
            print(format_table(rows))
            print()
            print(format_table(functions, PROFILE_COLUMNS))
            return
    print(format_table(rows))
