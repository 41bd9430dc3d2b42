"""Operators: Reconstruct, Flip Crossing, Save Run Settings, the cable colour (pick, automatic),
the preview.

Reconstruct and Flip Crossing have two modes, as Blender's own extension add-on does:
``execute()`` blocks (scripts, tests, background mode); ``invoke()`` runs the engine on a
worker thread, polls it from a 0.1 s timer, shows the stage and percentage in the panel and
the status bar, and cancels on Esc at once. The scene is only touched on the main thread when
the work has finished, so a cancelled or failed run leaves it as it was, and the result is one
undo step.
"""

import bpy
from bpy.props import BoolProperty, CollectionProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..engine.errors import Cancelled, InputError, ReconstructionError
from ..engine.pipeline import write_run
from ..engine.stages.segmentation import auto_colour, colour_at
from .background_job import CANCELLED, FAILED, FINISHED, RUNNING, BackgroundJob, ModalRun, \
    step_of
from .mask_preview import PREVIEW_IMAGE, frame_image, refresh_preview, show_preview
from .properties import set_colour_range
from .reconstruction import RunRequest, apply_outcome, flip_work, reconstruct_work, \
    request_from_scene

__all__ = ["CLASSES"]

_EXPECTED = (InputError, ReconstructionError)
_active = set()  # operators with a job running (one at a time)


def _redraw(context):
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type in {"VIEW_3D", "PROPERTIES"}:
                area.tag_redraw()


class _BackgroundWork:
    """The two modes shared by the operators whose work runs in the engine."""

    _title = "Working"

    @classmethod
    def poll(cls, context):
        return not _active

    def prepare(self, context):
        """``(work, finish)``: the engine work and what to do with its value on the main
        thread; raise :class:`InputError` or ``ValueError`` to refuse with a message."""
        raise NotImplementedError

    def _job(self, context):
        """The work as a :class:`BackgroundJob`, or None (refused, reported)."""
        try:
            work, self._finish = self.prepare(context)
        except (InputError, ReconstructionError, ValueError) as error:
            self.report({"ERROR"}, str(error))
            return None
        return BackgroundJob(work, expected_errors=_EXPECTED, cancelled_errors=(Cancelled,))

    def execute(self, context):
        job = self._job(context)
        if job is None:
            return {"CANCELLED"}
        return self._end(context, step_of(job.run_here(), self._title))

    def invoke(self, context, event):
        if context.window is None or bpy.app.background:  # no event loop: block
            return self.execute(context)
        job = self._job(context)
        if job is None:
            return {"CANCELLED"}
        self._run = ModalRun(job, title=self._title)
        _active.add(self)
        step = self._run.start()
        manager = context.window_manager
        self._timer = manager.event_timer_add(0.1, window=context.window)
        manager.modal_handler_add(self)
        self._show(context, step)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC" and event.value == "PRESS":
            step = self._run.on_escape()
        elif event.type == "TIMER":
            step = self._run.on_timer()
        else:
            return {"PASS_THROUGH"}
        if step.action == RUNNING:
            self._show(context, step)
            return {"RUNNING_MODAL"}
        context.window_manager.event_timer_remove(self._timer)
        _active.discard(self)
        self._show(context, None)
        return self._end(context, step)

    def _show(self, context, step):
        manager = context.window_manager
        manager.cable_recon_progress = step.fraction if step else 0.0
        manager.cable_recon_status = step.text if step else ""
        if context.workspace is not None:
            context.workspace.status_text_set(step.text if step else None)
        _redraw(context)

    def _end(self, context, step):
        if step.action == FINISHED:
            try:
                message = self._finish(context, step.value)
            except (InputError, ReconstructionError, ValueError) as error:
                self.report({"ERROR"}, str(error))
                return {"CANCELLED"}
            self.report({"INFO"}, message)
            return {"FINISHED"}
        if step.action == FAILED:
            self.report({"ERROR"}, step.text)
        elif step.action == CANCELLED:
            self.report({"WARNING"}, "Cancelled: the scene is unchanged")
        return {"CANCELLED"}


def _summary(obj, outcome):
    result = outcome.state.result
    text = (f"{obj.name}: {len(result.paths)} path(s), {len(result.crossings)} crossing(s), "
            f"{outcome.report['control_points']} control points (within "
            f"{outcome.report['max_error']:.3f} r)")
    if outcome.warnings:
        text += f"; {len(outcome.warnings)} warning(s): {outcome.warnings[0]}"
    return text


class CABLE_RECON_OT_reconstruct(_BackgroundWork, bpy.types.Operator):
    """Reconstruct the cable in the chosen images as a bevelled curve (Esc cancels)"""

    bl_idname = "cable_recon.reconstruct"
    bl_label = "Reconstruct Cable"
    bl_options = {"REGISTER", "UNDO"}
    _title = "Reconstructing"

    def prepare(self, context):
        request = request_from_scene(context.scene)

        def finish(context, outcome):
            return _summary(apply_outcome(context, request, outcome), outcome)
        return reconstruct_work(request), finish


def _result_object(context):
    obj = context.active_object
    if obj is None or obj.type != "CURVE" or not obj.cable_recon.arguments:
        return None
    return obj


class CABLE_RECON_OT_flip_crossing(_BackgroundWork, bpy.types.Operator):
    """Swap over and under at this crossing and re-run the final fit of the cable"""

    bl_idname = "cable_recon.flip_crossing"
    bl_label = "Flip Crossing"
    bl_options = {"REGISTER", "UNDO"}
    _title = "Re-fitting"

    index: IntProperty(name="Crossing", min=0, description="Which crossing to flip")

    @classmethod
    def poll(cls, context):
        return super().poll(context) and _result_object(context) is not None

    def prepare(self, context):
        obj = _result_object(context)
        count = len(obj.cable_recon.crossings)
        if self.index >= count:
            raise InputError(f"{obj.name} has no crossing {self.index} ({count} crossing(s))")
        request = RunRequest.from_json(obj.cable_recon.arguments)
        index = self.index

        def finish(context, outcome):
            new = apply_outcome(context, request, outcome)
            new.cable_recon.active_crossing = index
            return f"Crossing {index} flipped: " + _summary(new, outcome)
        return flip_work(request, obj.cable_recon.run, index), finish


class CABLE_RECON_OT_pick_colour(bpy.types.Operator):
    """Click the cable in the mask preview (Image Editor) to take its colour"""

    bl_idname = "cable_recon.pick_colour"
    bl_label = "Pick Cable Colour"
    bl_options = {"REGISTER", "UNDO"}

    x: IntProperty(name="X", min=0, description="Pixel column in the frame (from the left)")
    y: IntProperty(name="Y", min=0, description="Pixel row in the frame (from the top)")

    def execute(self, context):
        settings = context.scene.cable_recon
        try:
            frame, path = frame_image(settings)
            colour = colour_at(frame, self.x, self.y)
        except (InputError, ReconstructionError, ValueError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        set_colour_range(settings, colour)
        self.report({"INFO"}, f"Cable colour from {path.name} ({self.x}, {self.y}): {colour}")
        return {"FINISHED"}

    def invoke(self, context, event):
        if show_preview(context) is None:
            self.report({"ERROR"}, context.window_manager.cable_recon_status)
            return {"CANCELLED"}
        context.window.cursor_modal_set("EYEDROPPER")
        context.window_manager.modal_handler_add(self)
        if context.workspace is not None:
            context.workspace.status_text_set("Click the cable in the mask preview; Esc cancels")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type in {"ESC", "RIGHTMOUSE"} and event.value == "PRESS":
            self._stop(context)
            return {"CANCELLED"}
        if event.type == "LEFTMOUSE" and event.value == "PRESS":
            pixel = self._pixel_under(context, event)
            if pixel is None:
                return {"RUNNING_MODAL"}
            self._stop(context)
            self.x, self.y = pixel
            return self.execute(context)
        return {"RUNNING_MODAL"}

    def _stop(self, context):
        context.window.cursor_modal_restore()
        if context.workspace is not None:
            context.workspace.status_text_set(None)

    @staticmethod
    def _pixel_under(context, event):
        """The frame pixel under the mouse in an Image Editor showing the preview."""
        frame, _ = frame_image(context.scene.cable_recon)
        height, width = frame.shape[:2]
        for area in context.window.screen.areas:
            if area.type != "IMAGE_EDITOR" or area.spaces.active.image is None:
                continue
            if area.spaces.active.image.name != PREVIEW_IMAGE:
                continue
            for region in area.regions:
                if region.type != "WINDOW":
                    continue
                x, y = event.mouse_x - region.x, event.mouse_y - region.y
                if not (0 <= x < region.width and 0 <= y < region.height):
                    continue
                u, v = region.view2d.region_to_view(x, y)
                if 0 <= u < 1 and 0 <= v < 1:
                    return int(u * width), int((1 - v) * height)
        return None


class CABLE_RECON_OT_auto_colour(bpy.types.Operator):
    """Find the cable colour on the chosen frame (its dominant saturated colour)"""

    bl_idname = "cable_recon.auto_colour"
    bl_label = "Automatic Colour"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        settings = context.scene.cable_recon
        try:
            frame, path = frame_image(settings)
            colour = auto_colour(frame)
        except (InputError, ReconstructionError, ValueError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        set_colour_range(settings, colour)
        self.report({"INFO"}, f"Cable colour found on {path.name}: {colour}")
        return {"FINISHED"}


class CABLE_RECON_OT_show_preview(bpy.types.Operator):
    """Show the chosen frame's cable mask in an Image Editor; it follows every change"""

    bl_idname = "cable_recon.show_preview"
    bl_label = "Show Mask Preview"

    def execute(self, context):
        if show_preview(context) is None:
            self.report({"ERROR"}, context.window_manager.cable_recon_status)
            return {"CANCELLED"}
        self.report({"INFO"}, context.window_manager.cable_recon_status)
        return {"FINISHED"}


class CABLE_RECON_OT_set_images(bpy.types.Operator):
    """Use a folder of photos (or the folder of the images dropped) for the reconstruction"""

    bl_idname = "cable_recon.set_images"
    bl_label = "Cable Images"
    bl_options = {"REGISTER", "UNDO"}

    directory: StringProperty(subtype="DIR_PATH", options={"SKIP_SAVE"})
    files: CollectionProperty(type=bpy.types.OperatorFileListElement,
                              options={"HIDDEN", "SKIP_SAVE"})
    filter_image: bpy.props.BoolProperty(default=True, options={"HIDDEN", "SKIP_SAVE"})
    filter_folder: bpy.props.BoolProperty(default=True, options={"HIDDEN", "SKIP_SAVE"})

    def execute(self, context):
        if not self.directory:
            self.report({"ERROR"}, "no folder given")
            return {"CANCELLED"}
        settings = context.scene.cable_recon
        settings.images = self.directory
        refresh_preview(context)
        self.report({"INFO"}, f"Images: {self.directory}")
        return {"FINISHED"}

    def invoke(self, context, event):
        if self.directory:
            return self.execute(context)
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}


class CABLE_RECON_FH_images(bpy.types.FileHandler):
    """Drop photos of a cable onto the 3D viewport: their folder becomes the images."""

    bl_idname = "CABLE_RECON_FH_images"
    bl_label = "Cable Images"
    bl_import_operator = CABLE_RECON_OT_set_images.bl_idname
    bl_file_extensions = ".jpg;.jpeg;.png"

    @classmethod
    def poll_drop(cls, context):
        return context.area is not None and context.area.type == "VIEW_3D"


class CABLE_RECON_OT_save_run(bpy.types.Operator, ExportHelper):
    """Save the settings, colour and scale this curve was made with, for the command line:
    python -m engine reconstruct IMAGES --settings FILE repeats the run"""

    bl_idname = "cable_recon.save_run"
    bl_label = "Save Run Settings"
    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={"HIDDEN"})
    overwrite: BoolProperty(
        name="Overwrite", default=False, options={"HIDDEN", "SKIP_SAVE"},
        description="Replace an existing file (the file browser asks before it does)")

    @classmethod
    def poll(cls, context):
        return _result_object(context) is not None

    def invoke(self, context, event):
        self.overwrite = True  # chosen in the file browser, which marks an existing file
        return ExportHelper.invoke(self, context, event)

    def execute(self, context):
        request = RunRequest.from_json(_result_object(context).cable_recon.arguments)
        try:
            path = write_run(self.filepath, request.settings, request.inputs(),
                             overwrite=self.overwrite)
        except FileExistsError:
            self.report({"ERROR"}, f"{self.filepath} already exists: choose another name")
            return {"CANCELLED"}
        except (InputError, OSError) as error:
            self.report({"ERROR"}, f"cannot write {self.filepath}: {error}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Run settings saved to {path}: python -m engine reconstruct "
                              f"IMAGES --settings {path.name} repeats it")
        return {"FINISHED"}


CLASSES = (CABLE_RECON_OT_reconstruct, CABLE_RECON_OT_flip_crossing, CABLE_RECON_OT_save_run,
           CABLE_RECON_OT_pick_colour, CABLE_RECON_OT_auto_colour,
           CABLE_RECON_OT_show_preview, CABLE_RECON_OT_set_images, CABLE_RECON_FH_images)
