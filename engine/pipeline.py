"""The whole reconstruction: images to one continuous centreline per cable.

Stages, each timed in the result (the README's data flow)::

    masks + junctions (§3.1)   segmented here, or read from a folder written by ``segment``
    cameras (§3.2)             a COLMAP model given as is, or estimated with pycolmap (upright)
    agreement                  masks segmented here checked against what the other views
                               carve: strays removed, breaks filled
                               (``engine.stages.mask_agreement``)
    carving (§3.2)             occupancy and junction voxels
    segment graph (§3.3)       junctions, ends and segments on the hull's core
    topology (§3.5)            which branch continues which, over/under, one path per cable
    rod fit (§3.4, §3.6)       each whole path as one elastic rod, pulled onto the cable's 2D
                               centre in every view, with contact at its crossings
    radius and scale           the radius from the cable's width in the images; ``diameter`` or
                               ``length`` scales the world to metres
"""

import json
import logging
import threading
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from .errors import Cancelled, InputError, ReconstructionError
from .geometry.similarity import Similarity
from .geometry.upright import UprightSettings, make_upright
from .io.colmap import read_colmap_model
from .io.files import write_atomic
from .io.image_sequence import open_image_sequence, read_image
from .io.packed_mask import PackedMask, unpacked
from .io.result import CablePath, Crossing, Result, StrandRef
from .progress import AnySet, StageProgress, check_cancel
from .settings import check_settings, setting, settings_from_dict, settings_to_dict
from .stages.cameras import CameraEstimationSettings, estimate_cameras
from .stages.carving import CarvingSettings, carve
from .stages.core_ends import follow_free_ends
from .stages.mask_agreement import MaskAgreementSettings, agree_masks
from .stages.mask_checks import MaskCheckSettings, core_thickness, mask_warnings, unexplained_share
from .stages.rod_fit import Contact, ImageEvidence, Obstacle, RodFitSettings, Voxels, fit_rod
from .stages.segment_graph import SegmentGraphSettings, extract_segment_graph_from_voxels
from .stages.segmentation import (ColourRange, SegmentationSettings, cable_width, junction_map,
                                  reference_frames, segment_all, segment_frame,
                                  sequence_colour)
from .stages.topology import TopologySettings, resolve_topology
from .threads import map_in_threads, thread_count

__all__ = ["PipelineSettings", "RunInputs", "View", "Reconstruction", "reconstruct",
           "run_reconstruction", "read_run", "write_run", "run_record", "RUN_FORMAT",
           "measure_radius", "read_masks", "cable_colour", "segment_frames",
           "path_colours", "sequence_cameras"]

log = logging.getLogger(__name__)

#: Fewer registered views than this get a warning: the carved hull is loose (bench memory: 3
#: views put the curve 2 r off with a crossing wrong, 5 views 0.1 r).
_FEW_VIEWS = 5

#: Share of the progress bar per stage (cameras dominate when they are estimated).
_STAGES = {"masks": 0.10, "cameras": 0.35, "agreement": 0.15, "carving": 0.15, "graph": 0.05,
           "topology": 0.15, "fit": 0.20}


@dataclass(frozen=True)
class PipelineSettings:
    """Every stage's settings, in one place.

    Attributes
    ----------
    segmentation : SegmentationSettings
    cameras : CameraEstimationSettings
    agreement : MaskAgreementSettings
        How segmented masks are made to agree across views (``rounds=0``: not at all;
        masks given with ``masks`` are used as they are).
    carving : CarvingSettings
    graph : SegmentGraphSettings
    topology : TopologySettings
    fit : RodFitSettings
    upright : UprightSettings
        How the world is put upright (the table plane among the sparse points), for cameras
        estimated or from a model alike.
    checks : MaskCheckSettings
        When the run warns that its masks held more than the cable.
    reference_frame : int
        Frame the automatic cable colour is taken from.
    workers : int
        Threads for the work done frame by frame and view by view (the masks, their agreement
        across views, the topology's and the fit's reading of the views, the radius) and for
        making the masks while pycolmap estimates the cameras (0: one per CPU, at most
        :data:`~engine.threads.MOST_THREADS`; 1: all of it in turn on the calling thread).
        The result is the same on any number; each thread holds a frame's arrays. The carving
        has its own (``carving.threads``).
    """

    segmentation: SegmentationSettings = field(default_factory=SegmentationSettings)
    cameras: CameraEstimationSettings = field(default_factory=CameraEstimationSettings)
    agreement: MaskAgreementSettings = field(default_factory=MaskAgreementSettings)
    carving: CarvingSettings = field(default_factory=CarvingSettings)
    graph: SegmentGraphSettings = field(default_factory=SegmentGraphSettings)
    topology: TopologySettings = field(default_factory=TopologySettings)
    fit: RodFitSettings = field(default_factory=RodFitSettings)
    upright: UprightSettings = field(default_factory=UprightSettings)
    checks: MaskCheckSettings = field(default_factory=MaskCheckSettings)
    reference_frame: int = setting(0, low=0)
    workers: int = setting(0, low=0)

    def __post_init__(self):
        check_settings(self)


@dataclass(frozen=True)
class RunInputs:
    """The colour and scale a run is given, besides its settings: what its result records
    (:attr:`Result.run`) and ``--settings`` reads back.

    Attributes
    ----------
    hsv : str or None
        The colour range given (``"H1,S1,V1,H2,S2,V2"``); None: found automatically.
    diameter : float or None
        The cable's measured diameter in millimetres; None: not given.
    length : float or None
        The cable's length in metres; None: not given.
    """

    hsv: str = None
    diameter: float = None
    length: float = None

    #: Where the panel's colour range starts before the user sets or picks one (a red cable).
    PANEL_HSV = "170,80,40,10,255,255"
    #: Where the panel's diameter (mm) and length (m) start before the user measures them.
    PANEL_DIAMETER = 5.0
    PANEL_LENGTH = 1.0

    def __post_init__(self):
        if self.hsv is not None:
            ColourRange.parse(str(self.hsv))
        for key in ("diameter", "length"):
            value = getattr(self, key)
            if value is not None and (isinstance(value, bool)
                                      or not isinstance(value, (int, float))):
                raise InputError(f"the {key} must be a number or null")
        _check_scale(self.diameter, self.length)


@dataclass(frozen=True, eq=False)
class View:
    """One registered frame: its camera, a loader of its image, its masks.

    The masks are :class:`.PackedMask` (call one for its array): a long sequence of large
    frames keeps every view's masks in an eighth of the memory.
    """

    camera: object
    path: Path
    mask: PackedMask
    junctions: PackedMask

    def image(self):
        """The frame, RGB."""
        return read_image(self.path)


def read_masks(folder, names, width, height, *, packed=False):
    """Masks written by ``segment`` (possibly corrected by hand), one per frame.

    ``folder`` is the ``segment`` output folder (with ``masks/`` and ``junctions/``) or its
    ``masks/`` folder; a frame's mask is ``<stem>.png`` (cable > 127). Junction maps are read
    from the sibling ``junctions/`` folder when every frame has one, else made from the masks.
    With ``packed``, each is kept as a :class:`.PackedMask` as soon as it is read.

    Returns
    -------
    masks, junctions : list of ndarray of bool (or of PackedMask)
        ``junctions`` is None when they must be made from the masks.

    Raises
    ------
    InputError
        A frame has no mask, or a mask is unreadable or the wrong size.
    """
    folder = Path(folder)
    if (folder / "masks").is_dir():
        folder = folder / "masks"
    if not folder.is_dir():
        raise InputError(f"--masks {folder}: not a folder")
    junction_folder = folder.parent / "junctions"

    def load(path, what):
        # (a missing file is named here, not by OpenCV's warning on stderr)
        mask = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE | cv2.IMREAD_IGNORE_ORIENTATION) \
            if path.is_file() else None
        if mask is None:
            raise InputError(f"{what} {path} is missing or not an image")
        if mask.shape != (height, width):
            raise InputError(f"{what} {path} is {mask.shape[1]}x{mask.shape[0]}, the frames "
                             f"are {width}x{height}")
        return PackedMask(mask > 127) if packed else mask > 127

    masks = [load(folder / (Path(name).stem + ".png"), "mask") for name in names]
    junction_paths = [junction_folder / (Path(name).stem + ".png") for name in names]
    if all(path.is_file() for path in junction_paths):
        return masks, [load(path, "junction map") for path in junction_paths]
    return masks, None


def measure_radius(points, views, *, junction_margin=1.0, workers=1):
    """The cable's radius from its width in the images, along a fitted centreline.

    In every view, each centreline point that projects inside the frame, on the cable and away
    from junctions gives half the local width (the run of mask pixels through the point,
    across the projected centreline, sampled every tenth of a pixel: a mask of the pixels
    whose centres lie on the cable is as wide as the cable on average) times depth over
    focal length.

    Parameters
    ----------
    points : sequence of ndarray, shape (N, 3)
        The fitted centreline(s).
    views : sequence of View
    junction_margin : float, optional
        Points within this many cable widths of a junction pixel are left out.
    workers : int, optional
        Threads reading the views (0: one per CPU, at most
        :data:`~engine.threads.MOST_THREADS`); the radius is the same on any number.

    Returns
    -------
    float or None
        The mean of the middle half of the samples; None if there is none.
    """
    lines = [np.asarray(p, dtype=float) for p in points]
    tangents = np.concatenate([np.gradient(line, axis=0) if len(line) > 1
                               else np.zeros_like(line) for line in lines])
    points = np.concatenate(lines)
    samples = map_in_threads(workers, "radius", lambda view: _half_widths(
        view, points, tangents, junction_margin), views)
    samples = np.concatenate(samples) if samples else np.zeros(0)
    if not len(samples):
        return None
    # the middle half's mean: a run's length steps by whole pixels with the cable's position
    # on the pixel grid, so a median would be off by up to half a pixel
    low, high = np.percentile(samples, [25.0, 75.0])
    return float(np.mean(samples[(samples >= low) & (samples <= high)]))


def _half_widths(view, points, tangents, junction_margin):
    """:func:`measure_radius`'s samples of one view (world units; none for a view without
    cable)."""
    camera, mask = view.camera, unpacked(view.mask)
    if not mask.any():
        return np.zeros(0)
    width = cable_width(mask)
    grow = max(int(round(junction_margin * width)), 1)
    near_junction = cv2.dilate(unpacked(view.junctions).view(np.uint8),
                               np.ones((2 * grow + 1, 2 * grow + 1), np.uint8)) > 0
    pixels, depth = camera.project(points)
    ahead, _ = camera.project(points + tangents)
    with np.errstate(invalid="ignore"):
        col, row = np.floor(pixels[:, 0]), np.floor(pixels[:, 1])
        inside = ((depth > 0) & (col >= 0) & (row >= 0) & (col < camera.width)
                  & (row < camera.height))
    rows, cols = row[inside].astype(int), col[inside].astype(int)
    usable = np.flatnonzero(inside)[mask[rows, cols] & ~near_junction[rows, cols]]
    along = ahead[usable] - pixels[usable]
    length = np.linalg.norm(along, axis=1)
    usable, along = usable[length > 1e-9], along[length > 1e-9] / length[length > 1e-9, None]
    if not len(usable):
        return np.zeros(0)
    normal = np.column_stack([-along[:, 1], along[:, 0]])
    steps = np.arange(-int(np.ceil(20 * width)), int(np.ceil(20 * width)) + 1) * 0.1
    trace = pixels[usable, None, :] + steps[None, :, None] * normal[:, None, :]
    c, r = np.floor(trace[..., 0]).astype(int), np.floor(trace[..., 1]).astype(int)
    on_frame = (c >= 0) & (r >= 0) & (c < camera.width) & (r < camera.height)
    on = np.zeros(c.shape, dtype=bool)
    on[on_frame] = mask[r[on_frame], c[on_frame]]
    middle = len(steps) // 2
    # the run through the point: the first sample off the cable on either side
    after = np.argmin(on[:, middle:], axis=1)
    before = np.argmin(on[:, middle::-1], axis=1)
    closed = (after > 0) & (before > 0)  # the run ends within the samples on both sides
    run = 0.1 * (after + before - 1)
    return 0.5 * run[closed] * depth[usable][closed] / np.mean(camera.focal)


class _Clock:
    """Times the stages and moves the progress bar through their shares."""

    def __init__(self, progress, cancel, stages):
        self.progress, self.cancel = StageProgress(progress), cancel
        total = sum(_STAGES[name] for name in stages)
        self.slices, start = {}, 0.0
        for name in stages:
            self.slices[name] = (start / total, (start + _STAGES[name]) / total)
            start += _STAGES[name]
        self.timings, self.started, self.current = {}, {}, None

    def stage(self, name):
        check_cancel(self.cancel, "the reconstruction")
        self.current, self.started[name] = name, time.perf_counter()
        return self.progress.part(*self.slices[name])

    def side_by_side(self, names):
        """Start the stages ``names``, to run at once on different threads: a progress for
        each, moving the bar over their slices by the share of all their work done."""
        check_cancel(self.cancel, "the reconstruction")
        now = time.perf_counter()
        self.started.update((name, now) for name in names)
        self.timings.update((name, 0.0) for name in names)  # in the stages' order
        shares = {name: 0.0 for name in names}
        start = min(self.slices[name][0] for name in names)
        lock = threading.Lock()

        def progress_of(name):
            low, high = self.slices[name]

            def progress(fraction, message):
                with lock:  # one thread at a time reports, each its own share
                    shares[name] = (high - low) * min(max(fraction, 0.0), 1.0)
                    self.progress(start + sum(shares.values()), message)
            return StageProgress(progress)

        return {name: progress_of(name) for name in names}

    def done(self, name=None):
        name = self.current if name is None else name
        self.timings[name] = round(time.perf_counter() - self.started[name], 3)


def _segment(sequence, colour, settings, stage, cancel):
    check_cancel(cancel, "segmenting")
    reference = min(settings.reference_frame, len(sequence) - 1)
    frames = reference_frames(len(sequence), reference, settings.segmentation.model_frames)
    colour, model = sequence_colour([sequence.read(k) for k in frames], colour,
                                    settings.segmentation)
    masks, junctions, _ = segment_frames(sequence, colour, model, settings, progress=stage,
                                         cancel=cancel)
    return colour, masks, junctions


def segment_frames(sequence, colour, model, settings, *, progress=None, cancel=None):
    """Every frame of a sequence segmented (on ``settings.workers`` threads), a frame whose
    cable came out far thinner than in the others again
    (:func:`~engine.stages.segmentation.segment_all`).

    Parameters
    ----------
    sequence : ImageSequence
    colour : ColourRange
    model : ColourModel or None
        The sequence's colour model (:func:`~engine.stages.segmentation.sequence_colour`).
    settings : PipelineSettings
    progress : callable, optional
        ``progress(fraction, message)``, on the calling thread, after each frame in order.
    cancel : threading.Event, optional

    Returns
    -------
    masks, junctions : list of PackedMask
        Each frame's mask and junction map.
    widths : list of float
        Each frame's cable width in pixels.
    """
    def segmented(number, least_width):
        check_cancel(cancel, "segmenting")
        segmentation = segment_frame(sequence.read(number), colour, settings.segmentation,
                                     model=model, least_width=least_width)
        return (PackedMask(segmentation.mask), PackedMask(segmentation.junctions),
                segmentation.width)

    def done(number):
        if progress is not None:
            progress((number + 1) / len(sequence), f"masks: {sequence.names[number]}")

    def map_frames(function, numbers, first):  # the progress on the first pass
        return map_in_threads(settings.workers, "masks", function, numbers,
                              done if first else None)

    frames = segment_all(segmented, len(sequence), settings.segmentation, map_frames=map_frames,
                         width_of=lambda frame: frame[2])
    return [list(column) for column in zip(*frames)] if frames else [[], [], []]


def _cameras(sequence, cameras, settings, stage, cancel):
    """Cameras of the frames, the world's up direction and the warnings."""
    warnings = []
    if cameras is None:
        estimate = estimate_cameras(sequence.paths, settings=settings.cameras,
                                    focal_length_px=sequence.focal_length_px,
                                    progress=stage, cancel=cancel, upright=settings.upright)
        if estimate.unregistered:
            warnings.append(f"{len(estimate.unregistered)} frame(s) did not register and were "
                            f"left out: {', '.join(estimate.unregistered)}")
        return list(estimate.cameras), np.array([0.0, 0.0, 1.0]), warnings
    if isinstance(cameras, (str, Path)):
        model = read_colmap_model(cameras)
        cameras, points = list(model.cameras), model.points
    else:
        cameras, points = list(cameras), np.zeros((0, 3))
    names = set(sequence.names)
    known = [camera for camera in cameras if camera.name in names]
    if not known:
        raise InputError("no camera of the model is named after a frame "
                         f"(frames: {', '.join(sorted(names)[:3])}, ...)")
    for camera in known:
        if (camera.width, camera.height) != (sequence.width, sequence.height):
            raise InputError(f"the model's camera of {camera.name} is {camera.width}x"
                             f"{camera.height} but the frame is {sequence.width}x"
                             f"{sequence.height}: the model is of other images")
    missing = sorted(names - {camera.name for camera in known})
    if missing:
        warnings.append(f"{len(missing)} frame(s) have no camera and were left out: "
                        f"{', '.join(missing)}")
    # the model's frame is kept; "up" (for over and under) is its table normal or cameras' up
    _, _, transform, _ = make_upright(known, points, settings=settings.upright)
    stage(1.0, "cameras")
    return known, transform.R[2], warnings


def sequence_cameras(sequence, cameras=None, *, settings=PipelineSettings(), progress=None,
                     cancel=None):
    """The cameras of an open image sequence's frames, as a reconstruction gets them.

    Parameters
    ----------
    sequence : ImageSequence
    cameras : str, os.PathLike or sequence of Camera, optional
        A COLMAP model folder (or cameras) named after the frames; estimated with pycolmap
        (``settings.cameras``) if None.
    settings : PipelineSettings, optional
    progress : callable, optional
    cancel : threading.Event, optional

    Returns
    -------
    cameras : list of Camera
        One per frame that has one (registered, or named in the model).
    up : ndarray, shape (3,)
        The world's up direction.
    warnings : list of str
        Frames left out.

    Raises
    ------
    InputError
        No camera of the model is named after a frame.
    ReconstructionError
        Too few frames registered.
    Cancelled
    """
    return _cameras(sequence, cameras, settings, StageProgress(progress), cancel)


def _fit_paths(topology, evidence, voxels, radius, up, settings, stage, cancel):
    """One rod per path with contact at its crossings; crossings re-indexed into the fits.

    Paths are fitted in order; where a path crosses one fitted before it, that one is held
    fixed and the later path keeps its over/under clearance from it (:class:`Obstacle`).
    """
    fits = []
    span = settings.fit.contact_span * radius
    for number, path in enumerate(topology.paths):
        contacts = [Contact(over=c.over[1], under=c.under[1]) for c in topology.crossings
                    if c.over[0] == number and c.under[0] == number]
        obstacles = []
        for crossing in topology.crossings:
            for mine, theirs, over in ((crossing.over, crossing.under, True),
                                       (crossing.under, crossing.over, False)):
                if mine[0] == number and theirs[0] < number:
                    other = fits[theirs[0]]
                    centre = other.points[other.vertex_of(theirs[1])]
                    near = np.linalg.norm(other.points - centre, axis=1) <= span
                    obstacles.append(Obstacle(mine[1], other.points[near], over))
        part = stage.part(number / len(topology.paths), (number + 1) / len(topology.paths))
        nearby = voxels.near(path.points, 4.0 * radius)
        fits.append(fit_rod(path.points, radius, voxels=nearby, views=evidence,
                            contacts=contacts, obstacles=obstacles, closed=path.closed, up=up,
                            settings=settings.fit, progress=part, cancel=cancel))
    crossings = []
    for crossing in topology.crossings:
        (over_path, over_index), (under_path, under_index) = crossing.over, crossing.under
        over = StrandRef(over_path, fits[over_path].vertex_of(over_index))
        under = StrandRef(under_path, fits[under_path].vertex_of(under_index))
        position = 0.5 * (fits[over.path].points[over.index] + fits[under.path].points[under.index])
        crossings.append(Crossing(position, over, under,
                                  min(max(float(crossing.confidence), 0.0), 1.0)))
    return fits, crossings


def cable_colour(image, mask):
    """The cable's colour: the median of its pixels in one frame (sRGB, 0 to 1), or None."""
    pixels = np.asarray(image)[np.asarray(mask, dtype=bool)]
    if not len(pixels):
        return None
    return tuple(float(c) / 255.0 for c in np.median(pixels[:, :3], axis=0))


def path_colours(paths, camera, image, mask, *, reach=2):
    """Each path's colour in one frame: the median of the mask's pixels within ``reach``
    pixels of its projected centreline (sRGB, 0 to 1; None where it shows none).

    Parameters
    ----------
    paths : sequence
        Anything with ``points`` (N, 3) and ``closed``.
    camera : Camera
        The frame's camera.
    image, mask : ndarray
        The frame (RGB) and its cable mask.

    Returns
    -------
    tuple
    """
    mask = np.asarray(mask, dtype=bool)
    colours = []
    for path in paths:
        pixels, depth = camera.project(np.asarray(path.points))
        line = np.zeros(mask.shape, dtype=np.uint8)
        ahead = np.round(pixels[depth > 0] - 0.5).astype(np.int32)  # COLMAP: centres at +0.5
        if len(ahead) > 1:
            cv2.polylines(line, [ahead], bool(path.closed), 1, 2 * reach + 1)
        colours.append(cable_colour(image, (line > 0) & mask))
    return tuple(colours)


def _scale_factor(fits, radius, diameter, length):
    """The factor to metres asked for (``diameter`` in mm or ``length`` in m), or None."""
    if diameter is not None:
        return 0.5 * diameter / 1000.0 / radius
    if length is not None:
        return length / sum(_polyline_length(fit.points, fit.closed) for fit in fits)
    return None


def _polyline_length(points, closed):
    points = np.vstack([points, points[:1]]) if closed else np.asarray(points)
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def reconstruct(images, *, cameras=None, masks=None, colour=None, diameter=None, length=None,
                settings=PipelineSettings(), progress=None, cancel=None):
    """Reconstruct the cable(s) seen in a sequence of frames.

    The parameters, errors and stages are :func:`run_reconstruction`'s.

    Returns
    -------
    Result
    """
    return run_reconstruction(images, cameras=cameras, masks=masks, colour=colour,
                              diameter=diameter, length=length, settings=settings,
                              progress=progress, cancel=cancel).result


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """A finished reconstruction and what its final rod fit needs (§3.6).

    Keeping it lets a user flip a crossing that came out wrong and re-run only the final fit,
    a second or two, instead of the whole pipeline.

    Attributes
    ----------
    result : Result
        What :func:`reconstruct` returns.
    views : tuple of View
    topology : Topology
        The paths and crossings the fit started from (crossings in the result's order).
    evidence : tuple of ImageEvidence
    voxels : Voxels
    carved_radius : float
        The radius the grid was carved with (world units before scaling).
    up : ndarray, shape (3,)
    settings : PipelineSettings
    warnings : tuple of str
        Warnings of the stages before the fit.
    diameter, length : float or None
        The scale asked for.
    hsv : str or None
        The colour range asked for (``"H1,S1,V1,H2,S2,V2"``), None when found automatically.
    estimated : bool
        The cameras were estimated (so the scale is arbitrary unless asked for).
    colour : tuple of float or None
        The cable's colour (sRGB, 0 to 1).
    path_colours : tuple
        Each path's colour (:func:`path_colours`) when there are several, else empty.
    checks : dict
        The masks' checks (:mod:`engine.stages.mask_checks`): ``"core_thickness"`` and
        ``"unexplained"`` (the mean share of mask pixels away from the curve).
    """

    result: Result
    views: tuple
    topology: object
    evidence: tuple
    voxels: object
    carved_radius: float
    up: np.ndarray
    settings: PipelineSettings
    warnings: tuple
    diameter: float = None
    length: float = None
    hsv: str = None
    estimated: bool = False
    colour: tuple = None
    path_colours: tuple = ()
    checks: dict = field(default_factory=dict)

    def flip(self, index, *, progress=None, cancel=None):
        """The same reconstruction with crossing ``index`` flipped and the final fit re-run.

        Parameters
        ----------
        index : int
            Index into ``result.crossings`` (the same as ``topology.crossings``).
        progress : callable, optional
        cancel : threading.Event, optional

        Returns
        -------
        Reconstruction
            Its ``result.timings`` hold the re-fit's time only (``"fit"``).
        """
        if not 0 <= index < len(self.topology.crossings):
            raise IndexError(f"there is no crossing {index} "
                             f"({len(self.topology.crossings)} crossing(s))")
        state = replace(self, topology=self.topology.flipped(index), result=None)
        clock = _Clock(progress, cancel, ["fit"])
        return state._fitted(clock, clock.stage("fit"), cancel)

    def _fitted(self, clock, stage, cancel):
        fits, crossings = _fit_paths(self.topology, self.evidence, self.voxels,
                                     self.carved_radius, self.up, self.settings, stage, cancel)
        clock.done()
        result, unexplained = _finish(fits, crossings, self, clock)
        return replace(self, result=result, checks={**self.checks, "unexplained": unexplained})


#: The format of a run file (the settings and inputs of a run, without its result).
RUN_FORMAT = "cable_recon.run/1"


def run_record(settings, inputs):
    """What a result records of its run (:attr:`Result.run`): every stage's settings and the
    colour and scale given.

    Parameters
    ----------
    settings : PipelineSettings
    inputs : RunInputs

    Returns
    -------
    dict
    """
    return {"settings": settings_to_dict(settings), "inputs": asdict(inputs)}


def write_run(path, settings, inputs, *, overwrite=False):
    """Write a run file (``"format": "cable_recon.run/1"``): what ``reconstruct --settings``
    reads to repeat a run made elsewhere (in Blender).

    Parameters
    ----------
    path : str or os.PathLike
    settings : PipelineSettings
    inputs : RunInputs
    overwrite : bool, optional
        Replace an existing file (:class:`FileExistsError` otherwise).

    Returns
    -------
    pathlib.Path
    """
    document = {"format": RUN_FORMAT, "run": run_record(settings, inputs)}
    return write_atomic(path, json.dumps(document, indent=1) + "\n", overwrite=overwrite)


def read_run(path):
    """The settings and inputs a run was made with, from its result file (or a run file the
    add-on saves): ``(settings, inputs)``.

    Parameters
    ----------
    path : str or os.PathLike
        A JSON file holding a ``"run"`` object (:attr:`Result.run`).

    Returns
    -------
    settings : PipelineSettings
    inputs : RunInputs

    Raises
    ------
    InputError
        The file cannot be read, holds no run, or a setting or input does not fit.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except OSError as error:
        raise InputError(f"cannot read {path}: {error.strerror or error}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise InputError(f"{path} is not a JSON file: {error}") from None
    run = data.get("run") if isinstance(data, dict) else None
    if not isinstance(run, dict):
        raise InputError(f"{path} records no run (a result written by this version, or a run "
                         "file saved in Blender, has one)")
    settings = settings_from_dict(PipelineSettings, run.get("settings", {}),
                                  f"{path}: run.settings")
    inputs = run.get("inputs", {})
    if not isinstance(inputs, dict) or set(inputs) - {"hsv", "diameter", "length"}:
        raise InputError(f"{path}: run.inputs holds hsv, diameter and length only")
    try:
        return settings, RunInputs(**inputs)
    except (InputError, ValueError) as error:
        raise InputError(f"{path}: run.inputs: {error}") from None


def _core_graph(grid, core, settings, stage, cancel):
    """The segment graph of the grid's ``core`` voxels."""
    return extract_segment_graph_from_voxels(
        grid.index[core], grid.junction[core], origin=grid.origin, voxel_size=grid.voxel_size,
        radius=grid.radius, settings=settings.graph, progress=stage, cancel=cancel)


def run_reconstruction(images, *, cameras=None, masks=None, colour=None, diameter=None,
                       length=None, settings=PipelineSettings(), progress=None, cancel=None):
    """Reconstruct the cable(s) seen in a sequence of frames, keeping what a re-fit needs.

    :func:`reconstruct` is this function's ``.result``; the :class:`Reconstruction` it returns
    can also flip a crossing and re-run only the final rod fit.

    Parameters
    ----------
    images : str or os.PathLike
        A folder of .jpg/.png frames (natural order) or a video.
    cameras : str, os.PathLike or sequence of Camera, optional
        A COLMAP model folder (or cameras) whose image names are the frames' file names, used
        as is (its world frame and units kept); estimated with pycolmap if None (upright, the
        table at z = 0, arbitrary scale).
    masks : str or os.PathLike, optional
        Masks written by ``segment`` (possibly corrected by hand), used instead of segmenting.
    colour : ColourRange, optional
        The cable colour; found automatically on ``settings.reference_frame`` if None.
    diameter : float, optional
        The cable's measured diameter in millimetres: the result is scaled to metres.
    length : float, optional
        The cable's length in metres: the result is scaled to metres.
    settings : PipelineSettings, optional
    progress : callable, optional
        ``progress(fraction, message)``.
    cancel : threading.Event, optional

    Returns
    -------
    Reconstruction

    Raises
    ------
    InputError
        Unusable input (empty folder, unreadable or mixed-size frames, masks that do not
        match, a model with no camera named after a frame, both ``diameter`` and ``length``).
    ReconstructionError
        Too few frames registered, no cable in the frames, or no path could be formed.
    Cancelled
    """
    _check_scale(diameter, length)
    if colour is not None and not isinstance(colour, ColourRange):
        colour = ColourRange.parse(str(colour))
    hsv = None if colour is None else str(colour)
    agree = masks is None and settings.agreement.rounds > 0
    stages = ["masks", "cameras"] + (["agreement"] if agree else []) + [
        "carving", "graph", "topology", "fit"]
    clock = _Clock(progress, cancel, stages)
    with open_image_sequence(images) as sequence:
        (colour, frame_masks, frame_junctions), found = _masks_and_cameras(
            sequence, masks, colour, cameras, settings, clock, cancel)
        views, frame_masks, up, warnings = _views(sequence, found, frame_masks,
                                                  frame_junctions, agree, settings, clock,
                                                  cancel)
        grid, topology, warnings, thickness = _carve_and_resolve(views, up, clock, settings,
                                                                 cancel, warnings)
        colour_seen, colours = _colours_seen(sequence, frame_masks, views, topology, settings)
    stage = clock.stage("fit")

    def read_view(view):
        check_cancel(cancel, "the reconstruction")
        return ImageEvidence.from_mask(view.camera, unpacked(view.mask),
                                       unpacked(view.junctions), settings=settings.fit)

    evidence = map_in_threads(settings.workers, "evidence", read_view, views)
    voxels = Voxels.from_grid(grid, agreement=settings.carving.core_agreement)
    state = Reconstruction(
        result=None, views=tuple(views), topology=topology, evidence=tuple(evidence),
        voxels=voxels, carved_radius=grid.radius, up=up, settings=settings,
        warnings=tuple(warnings), diameter=diameter, length=length, hsv=hsv,
        estimated=cameras is None, colour=colour_seen, path_colours=colours,
        checks={"core_thickness": thickness})
    return state._fitted(clock, stage, cancel)


def _check_scale(diameter, length):
    """The cable's diameter or its length, not both, each positive (an InputError otherwise)."""
    if diameter is not None and length is not None:
        raise InputError("give the cable's diameter or its length, not both")
    for name, value in (("diameter", diameter), ("length", length)):
        if value is not None and not value > 0:
            raise InputError(f"the {name} must be a positive number")


def _masks_and_cameras(sequence, masks, colour, cameras, settings, clock, cancel):
    """The "masks" and "cameras" stages: ``(colour, masks, junctions)`` of every frame and
    ``(cameras, up, warnings)``.

    pycolmap matches and maps on one thread (see ``CameraEstimationSettings.deterministic``),
    so while it estimates the cameras the masks are made on a thread of their own (when
    ``settings.workers`` gives more than one thread). Either's failure stops the other. The
    error raised is the masks' (as when they are made first), unless they were only stopped
    because the cameras failed: then it is the cameras'.
    """
    if cameras is not None or thread_count(settings.workers) < 2:
        made = _frame_masks(sequence, masks, colour, settings, clock.stage("masks"), cancel)
        clock.done()
        found = _cameras(sequence, cameras, settings, clock.stage("cameras"), cancel)
        clock.done()
        return made, found
    progress = clock.side_by_side(("masks", "cameras"))
    failed = threading.Event()
    stop = AnySet(cancel, failed)
    outcome = {}

    def make_masks():
        try:
            outcome["made"] = _frame_masks(sequence, masks, colour, settings,
                                           progress["masks"], stop)
        except BaseException as error:  # noqa: BLE001 - raised on the calling thread
            outcome["error"] = error
            failed.set()
        finally:
            clock.done("masks")

    worker = threading.Thread(target=make_masks, name="masks", daemon=True)
    worker.start()
    try:
        found = _cameras(sequence, None, settings, progress["cameras"], stop)
        clock.done("cameras")
        worker.join()
    except BaseException:  # the cameras failed (or Ctrl-C): stop the masks, then say why
        failed.set()
        worker.join()
        error = outcome.get("error")
        if error is not None and not isinstance(error, Cancelled):
            raise error from None
        raise
    if "error" in outcome:
        raise outcome["error"]
    return outcome["made"], found


def _frame_masks(sequence, masks, colour, settings, stage, cancel):
    """``(colour, masks, junctions)`` of every frame, read from the folder ``masks`` or
    segmented (the colour found if None)."""
    if masks is not None:
        frame_masks, frame_junctions = read_masks(masks, sequence.names, sequence.width,
                                                  sequence.height, packed=True)
        if frame_junctions is None:
            frame_junctions = map_in_threads(
                settings.workers, "junctions",
                lambda mask: _junctions_of(mask(), settings.segmentation), frame_masks)
        stage(1.0, "masks")
    else:
        colour, frame_masks, frame_junctions = _segment(sequence, colour, settings, stage,
                                                        cancel)
    if not any(mask.any() for mask in frame_masks):
        raise ReconstructionError("no cable pixels in any frame: check the cable colour "
                                  "(python -m engine segment shows the masks)")
    return colour, frame_masks, frame_junctions


def _views(sequence, found, frame_masks, frame_junctions, agree, settings, clock, cancel):
    """The views of the ``found`` cameras (:func:`_cameras`) and the "agreement" stage:
    ``(views, frame_masks, up, warnings)``, the frames' masks as agreed across the views."""
    empty = [name for name, mask in zip(sequence.names, frame_masks) if not mask.any()]
    frame_cameras, up, warnings = found
    if empty:
        warnings.append(f"no cable pixels in {len(empty)} frame(s): {', '.join(empty)}")
    if len(frame_cameras) < _FEW_VIEWS:
        warnings.append(f"only {len(frame_cameras)} views: so few leave the cable's shape "
                        f"and crossings ambiguous; take {2 * _FEW_VIEWS} or more around it")
    by_name = dict(zip(sequence.names, zip(sequence.paths, frame_masks, frame_junctions)))
    views = [View(camera, *by_name[camera.name]) for camera in frame_cameras]
    if agree:
        stage = clock.stage("agreement")
        views, alone = _agree(views, settings, stage, cancel)
        clock.done()
        if alone:
            warnings.append(f"the masks of {len(alone)} frame(s) disagree with the other "
                            f"views and were used as they are: {', '.join(alone)}")
        agreed = {view.camera.name: view.mask for view in views}
        frame_masks = [agreed.get(name, mask)
                       for name, mask in zip(sequence.names, frame_masks)]
    return views, frame_masks, up, warnings


def _colours_seen(sequence, frame_masks, views, topology, settings):
    """The cable's colour in the reference frame (or, without cable there, the first frame with
    some) and,
    with several paths, each path's colour there."""
    reference = min(settings.reference_frame, len(sequence) - 1)
    order = [reference] + [k for k in range(len(sequence)) if k != reference]
    number = next((k for k in order if frame_masks[k].any()), reference)
    image, mask = sequence.read(number), frame_masks[number]()
    colour_seen = cable_colour(image, mask)
    camera = next((view.camera for view in views
                   if view.camera.name == sequence.names[number]), None)
    colours = path_colours(topology.paths, camera, image, mask) \
        if len(topology.paths) > 1 and camera is not None else ()
    return colour_seen, colours


def _junctions_of(mask, settings):
    """The junction map of a mask given without one, packed."""
    return PackedMask(junction_map(mask, cable_width(mask), settings))


def _agree(views, settings, stage, cancel):
    """The views with their masks agreed across views (:func:`agree_masks`), and the names
    of the frames whose masks were left as they were."""
    masks, report = agree_masks([view.camera for view in views], [view.mask for view in views],
                                junctions=[view.junctions for view in views],
                                carving=settings.carving, settings=settings.agreement,
                                segmentation=settings.segmentation, progress=stage,
                                cancel=cancel, packed=True, workers=settings.workers)
    log.info(report.summary())
    views = [replace(view, mask=mask, junctions=junctions)
             for view, mask, junctions in zip(views, masks, report.junctions)]
    return views, list(report.left_alone)


def _carve_and_resolve(views, up, clock, settings, cancel, warnings):
    stage = clock.stage("carving")
    try:
        grid = carve([v.camera for v in views], [v.mask for v in views],
                     [v.junctions for v in views], settings=settings.carving, progress=stage,
                     cancel=cancel)
    except ValueError as error:
        raise ReconstructionError(f"carving failed: {error}") from None
    clock.done()
    if not len(grid):
        raise ReconstructionError("the frames do not agree on any cable voxel: the cameras or "
                                  "the masks are wrong")
    wanted = grid.radius / settings.carving.voxels_per_radius
    if grid.voxel_size > 1.01 * wanted:
        warnings = list(warnings) + [
            f"the carving's grid is {grid.voxel_size / wanted:.0f} times coarser than asked "
            f"({grid.radius / grid.voxel_size:.1f} voxels per radius) to stay within its memory "
            f"budget of {settings.carving.memory_mb:.0f} MB (--memory-mb): crossings close "
            f"together may be missed"]
    stage = clock.stage("graph")
    core = grid.core(settings.carving.core_agreement)
    graph = _core_graph(grid, core, settings, stage, cancel)
    core, followed = follow_free_ends(grid, core, graph, up=up,
                                      length=settings.carving.follow_length * grid.radius)
    if followed:
        for walk in followed:
            log.info("free end followed %.1f r through the hull", walk.length / grid.radius)
        graph = _core_graph(grid, core, settings, stage, cancel)
    clock.done()
    if graph.n_segments == 0:
        raise ReconstructionError("no cable segment could be found in the carved volume")
    length = sum(_polyline_length(points, False) for *_, points in graph.segments())
    thickness = core_thickness(int(np.count_nonzero(core)), grid.voxel_size, grid.radius, length)
    log.info("carved core: %.2f times a tube's volume", thickness)
    # the masks' warnings first: the likeliest cause of the others, and what a user can mend
    warnings = mask_warnings(thickness=thickness, settings=settings.checks) + list(warnings)
    stage = clock.stage("topology")
    topology = resolve_topology(graph, views, radius=grid.radius, up=up,
                                settings=settings.topology, progress=stage, cancel=cancel,
                                workers=settings.workers)
    topology = _fittable(topology, settings.fit.spacing, grid.radius)
    clock.done()
    return grid, topology, list(warnings) + list(topology.warnings), thickness


def _fittable(topology, spacing, radius):
    """``topology`` without the paths no longer than one vertex spacing of the fit (``spacing``
    radii): a speck the topology keeps when no path is as long as its ``min_path_length``
    (masks that hold only specks of the cable); a ReconstructionError when none is longer."""
    lengths = [_polyline_length(path.points, False) for path in topology.paths]
    keep = [k for k, length in enumerate(lengths) if length > spacing * radius]
    if not keep:
        raise ReconstructionError(
            f"no path could be formed: the longest piece of cable in the carved volume is "
            f"{max(lengths, default=0.0) / radius:.1f} r long (do the masks hold only specks of "
            f"the cable? check its colour)")
    if len(keep) == len(lengths):
        return topology
    number = {old: new for new, old in enumerate(keep)}
    crossings = tuple(replace(c, over=(number[c.over[0]], c.over[1]),
                              under=(number[c.under[0]], c.under[1]))
                      for c in topology.crossings if c.over[0] in number and c.under[0] in number)
    dropped = tuple(f"dropped a piece of cable {lengths[k] / radius:.1f} r long (too short to fit)"
                    for k in range(len(lengths)) if k not in number)
    return replace(topology, paths=tuple(topology.paths[k] for k in keep), crossings=crossings,
                   warnings=tuple(topology.warnings) + dropped)


def _finish(fits, crossings, state, clock):
    warnings = list(state.warnings)
    for number, fit in enumerate(fits):
        named = f"path {number + 1}: " if len(fits) > 1 else ""
        warnings.extend(named + warning for warning in fit.warnings)
        if not fit.converged:
            warnings.append(f"{named}the final fit stopped before it converged: the curve may "
                            "be a little off the cable")
    radius = measure_radius([fit.points for fit in fits], state.views,
                            workers=state.settings.workers)
    if not radius:
        radius = state.carved_radius
        warnings.append("the cable's radius could not be measured in the frames: it is the "
                        "carving's estimate")
    shares = unexplained_share([(fit.points, fit.closed) for fit in fits], radius, state.views,
                               band=state.settings.checks.band)
    unexplained = float(np.mean([share for _, share in shares])) if shares else 0.0
    warnings = mask_warnings(shares=shares, settings=state.settings.checks) + warnings
    scale = _scale_factor(fits, radius, state.diameter, state.length)
    cameras = [view.camera for view in state.views]
    units = "model"
    if scale is not None:
        similarity = Similarity(scale=scale, R=np.eye(3), t=np.zeros(3))
        fits_points = [similarity.apply(fit.points) for fit in fits]
        cameras = [similarity.apply_camera(camera) for camera in cameras]
        crossings = [Crossing(similarity.apply(c.position[None])[0], c.over, c.under,
                              c.confidence) for c in crossings]
        radius, units = radius * scale, "m"
    else:
        fits_points = [fit.points for fit in fits]
        if state.estimated:
            warnings.append("the cameras were estimated, so the scale is arbitrary: give "
                            "--diameter or --length for metres")
    colours = state.path_colours or (None,) * len(fits)
    paths = [CablePath(points, closed=fit.closed, colour=colour)
             for points, fit, colour in zip(fits_points, fits, colours)]
    clock.progress(1.0, "done")
    run = run_record(state.settings, RunInputs(state.hsv, state.diameter, state.length))
    return Result(radius=radius, paths=paths, crossings=crossings, cameras=cameras, units=units,
                  warnings=warnings, timings=dict(clock.timings),
                  colour=state.colour, run=run), unexplained
