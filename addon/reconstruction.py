"""From the panel's settings to the engine, and the engine's result into the scene.

A :class:`RunRequest` is plain data captured on the main thread; the work functions run the
engine with it on any thread (they never touch bpy); :func:`apply_outcome` builds the scene on
the main thread. The engine's :class:`~engine.pipeline.Reconstruction` of the last few runs is
kept in memory so flipping a crossing re-runs only the final rod fit; after Blender restarts a
flip re-runs the whole reconstruction from the arguments stored on the curve object.
"""

import dataclasses
import json
import uuid
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

import bpy

from ..engine.errors import InputError
from ..engine.pipeline import (PipelineSettings, Reconstruction, RunInputs,
                               run_reconstruction)
from ..engine.progress import StageProgress
from ..engine.settings import settings_from_dict
from ..engine.stages.bezier import BezierSettings, fit_result_curves
from ..engine.stages.segmentation import ColourRange
from .mask_preview import frame_paths
from .properties import colour_range, pipeline_settings
from .scene_objects import (add_cable_materials, build_bezier_curve, build_cameras,
                            remove_collection)
from .settings_properties import settings_from_group

__all__ = ["RunRequest", "Outcome", "request_from_scene", "reconstruct_work", "flip_work",
           "apply_outcome", "outcome_of_result", "sessions", "sequence_name"]

#: Engine state of the last runs, by run id (to flip a crossing without re-running it all).
sessions = OrderedDict()
MAX_SESSIONS = 3
#: Custom property of a result's collection: which image folder it reconstructs.
SOURCE_KEY = "cable_recon_images"


@dataclass(frozen=True)
class RunRequest:
    """Everything a reconstruction needs, as plain data (JSON-able but for the settings).

    Attributes
    ----------
    images : str
        Absolute path of the frames' folder (or video).
    name : str
        The sequence's name: the collection and the curve are named after it.
    cameras, masks : str or None
        A COLMAP model folder, a masks folder.
    hsv : str or None
        The colour range (``"H1,S1,V1,H2,S2,V2"``), None for automatic.
    diameter, length : float or None
        The scale asked for (mm, m).
    settings : PipelineSettings
    curve : BezierSettings
    with_cameras, background_images : bool
    """

    images: str
    name: str
    cameras: str = None
    masks: str = None
    hsv: str = None
    diameter: float = None
    length: float = None
    settings: PipelineSettings = field(default_factory=PipelineSettings)
    curve: BezierSettings = field(default_factory=BezierSettings)
    with_cameras: bool = True
    background_images: bool = True

    def engine_arguments(self):
        """Keyword arguments of :func:`engine.pipeline.run_reconstruction`."""
        return dict(images=self.images, cameras=self.cameras, masks=self.masks,
                    colour=ColourRange.parse(self.hsv) if self.hsv else None,
                    diameter=self.diameter, length=self.length, settings=self.settings)

    def to_json(self):
        """The request as a JSON string (stored on the curve object)."""
        return json.dumps(dataclasses.asdict(self))

    @classmethod
    def from_json(cls, text):
        """The request stored by :meth:`to_json`."""
        data = json.loads(text)
        # a curve made by an earlier version may name settings since moved or merged
        data["settings"] = settings_from_dict(PipelineSettings, data["settings"], strict=False)
        data["curve"] = settings_from_dict(BezierSettings, data["curve"], strict=False)
        return cls(**data)

    def inputs(self):
        """The colour and scale given, as a run records them."""
        return RunInputs(hsv=self.hsv, diameter=self.diameter, length=self.length)


@dataclass(frozen=True, eq=False)
class Outcome:
    """What a work function returns: the engine's state, the Bézier curves, their report."""

    state: object
    curves: list
    report: dict

    @property
    def warnings(self):
        """The reconstruction's warnings, then the curve fit's."""
        return list(self.state.result.warnings) + list(self.report.get("warnings", ()))


def _absolute(path):
    return str(Path(bpy.path.abspath(path)).resolve()) if path else None


def request_from_scene(scene):
    """A :class:`RunRequest` from ``scene.cable_recon``.

    Raises
    ------
    InputError
        No folder, a folder without frames, no model folder while the model is the source.
    ValueError
        An impossible HSV range.
    """
    settings = scene.cable_recon
    if not settings.images:
        raise InputError("choose the folder of the cable's images first")
    images = _absolute(settings.images)
    if not Path(images).exists():
        raise InputError(f"{images} does not exist")
    if Path(images).is_dir() and not frame_paths(images):
        raise InputError(f"{images} holds no .jpg or .png images")
    cameras = None
    if settings.camera_source == "MODEL":
        if not settings.camera_model:
            raise InputError("choose the COLMAP model's folder, or let the cameras be estimated")
        cameras = _absolute(settings.camera_model)
    colour = colour_range(settings)
    return RunRequest(
        images=images, name=sequence_name(images), cameras=cameras,
        masks=_absolute(settings.masks), hsv=str(colour) if colour else None,
        diameter=settings.diameter if settings.scale == "DIAMETER" else None,
        length=settings.length if settings.scale == "LENGTH" else None,
        settings=pipeline_settings(settings), curve=settings_from_group(settings.curve),
        with_cameras=settings.with_cameras, background_images=settings.background_images)


#: Folder names that say nothing about the sequence: its parent names it instead.
_GENERIC_FOLDERS = {"images", "frames", "photos", "input", "jpg", "png"}


def sequence_name(images):
    """The name of a sequence: its folder's (or video's) name, or the parent's if generic."""
    path = Path(images)
    if path.name.lower() in _GENERIC_FOLDERS and path.parent.name:
        return path.parent.name
    return path.stem or "cable"


def _curves(state, request, progress):
    progress(0.0, "curve")
    curves, report = fit_result_curves(state.result, settings=request.curve)
    progress(1.0, "curve")
    return Outcome(state, curves, report)


@dataclass(frozen=True, eq=False)
class _ReadResult:
    """The engine state of a result read from a file: the result alone (a flip re-runs the
    reconstruction from the arguments stored on the curve, as after Blender restarts)."""

    result: object


def outcome_of_result(result, request):
    """The :class:`Outcome` of a result read from a file (the Bézier curves fitted to it)."""
    return _curves(_ReadResult(result), request, lambda fraction, message: None)


def reconstruct_work(request):
    """``work(progress, cancel)``: the whole reconstruction, then the Bézier curves."""
    def work(progress, cancel):
        bar = StageProgress(progress)
        state = run_reconstruction(**request.engine_arguments(), progress=bar.part(0.0, 0.97),
                                   cancel=cancel)
        return _curves(state, request, bar.part(0.97, 1.0))
    return work


def flip_work(request, run, index):
    """``work(progress, cancel)``: flip crossing ``index`` and re-run the final fit.

    Parameters
    ----------
    request : RunRequest
        How the curve was made (used when the run's state is no longer in memory).
    run : str
        The run's id.
    index : int
    """
    state = sessions.get(run)

    def work(progress, cancel):
        bar = StageProgress(progress)
        current = state
        if current is None:  # e.g. Blender restarted: everything again, then the flip
            current = run_reconstruction(**request.engine_arguments(),
                                         progress=bar.part(0.0, 0.8), cancel=cancel)
            bar = bar.part(0.8, 1.0)
        flipped = current.flip(index, progress=bar.part(0.0, 0.95), cancel=cancel)
        return _curves(flipped, request, bar.part(0.95, 1.0))
    return work


def apply_outcome(context, request, outcome):
    """Put a finished run into the scene, replacing an earlier result of the same images.

    Everything is built in a new collection first; only when that worked is the previous
    result of the same image folder removed, so a failure leaves the scene as it was.

    Returns
    -------
    bpy.types.Object
        The new curve object (selected and active).
    """
    result = outcome.state.result
    collection = bpy.data.collections.new(request.name)
    try:
        obj = build_bezier_curve(result, outcome.curves, request.name, collection)
        add_cable_materials(obj, result, request.name)
        _remember(obj, request, outcome)
        if request.with_cameras and result.cameras:
            cameras = bpy.data.collections.new(f"{request.name} cameras")
            collection.children.link(cameras)
            frames = ({path.name: path for path in frame_paths(request.images)}
                      if request.background_images else None)
            prefix = f"{request.name} "
            built = build_cameras(result.cameras, cameras, name_prefix=prefix, frames=frames)
            for camera, engine_camera in zip(built, result.cameras):
                camera["cable_recon_name"] = prefix + engine_camera.name
    except BaseException:
        remove_collection(collection)
        raise
    for other in context.view_layer.objects:
        if other.select_get():
            other.select_set(False)
    for old in [c for c in bpy.data.collections if c.get(SOURCE_KEY) == request.images]:
        remove_collection(old)
    # built beside the old result, so names got ".001": now they can have their own
    collection.name = request.name
    for child in collection.children:
        child.name = f"{request.name} cameras"
    for item in collection.all_objects:
        intended = item.get("cable_recon_name", request.name)
        item.name = intended
        if item.data is not None and item.data.users == 1:
            item.data.name = intended
    collection[SOURCE_KEY] = request.images
    context.scene.collection.children.link(collection)
    obj.select_set(True)
    context.view_layer.objects.active = obj
    return obj


def _remember(obj, request, outcome):
    result, props = outcome.state.result, obj.cable_recon
    run = uuid.uuid4().hex
    if isinstance(outcome.state, Reconstruction):  # a result read from a file cannot flip
        sessions[run] = outcome.state
    while len(sessions) > MAX_SESSIONS:
        sessions.popitem(last=False)
    props.run = run
    props.arguments = request.to_json()
    props.radius = result.radius
    props.control_points = outcome.report["control_points"]
    props.max_error = outcome.report["max_error"]
    props.crossings.clear()
    for crossing in result.crossings:
        item = props.crossings.add()
        item.over_path, item.over_index = crossing.over.path, crossing.over.index
        item.under_path, item.under_index = crossing.under.path, crossing.under.index
        item.confidence = crossing.confidence
        item.position = crossing.position.tolist()
    obj["cable_recon_warnings"] = outcome.warnings
