"""Synthetic scenes: a layout, cameras around it, and its views, kept or written to disk.

A written scene is a folder a user's capture would look like, plus what is really there::

    images/000.png ...      colour views
    masks/000.png ...       exact cable masks (cable = 255), same stems
    sparse/                 COLMAP text model of the true cameras
    ground_truth.json       cable_recon.ground_truth/1
"""

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .colmap_model import write_colmap_model
from .ground_truth import write_ground_truth
from .synthetic_cameras import cable_pixel_width, handheld_cameras, orbit_cameras
from .synthetic_layouts import hanging_layout, knot_layout, table_layout
from .synthetic_render import RenderSettings, render_views

__all__ = ["SceneSpec", "SyntheticScene", "make_scene", "write_scene", "MIN_CABLE_PIXELS"]

#: Nothing can be reconstructed from a thinner wire; scenes are always at least this wide.
MIN_CABLE_PIXELS = 5.0


@dataclass(frozen=True)
class SceneSpec:
    """What to generate.

    Attributes
    ----------
    kind : str
        ``"table"``, ``"loop"`` (a closed cable on the table), ``"knot"`` or ``"hanging"``.
    crossings : int
        For ``"table"`` and ``"loop"``.
    seed : int
    radius : float
        Metres.
    extent : float or None
        Metres; derived from the radius and crossings if None.
    views : int
    rig : str
        ``"orbit"`` or ``"handheld"``.
    width, height : int
        Image size.
    image_format : str
        ``"png"`` or ``"jpg"``.
    """

    kind: str = "table"
    crossings: int = 3
    seed: int = 0
    radius: float = 0.004
    extent: float = None
    views: int = 30
    rig: str = "orbit"
    width: int = 960
    height: int = 720
    image_format: str = "png"

    def layout(self):
        """The scene's ground truth, without cameras."""
        common = dict(seed=self.seed, radius=self.radius, extent=self.extent)
        if self.kind == "table":
            return table_layout(self.crossings, **common)
        if self.kind == "loop":
            return table_layout(self.crossings, closed=True, **common)
        if self.kind == "knot":
            return knot_layout(**common)
        if self.kind == "hanging":
            return hanging_layout(**common)
        raise ValueError(f"unknown scene kind {self.kind!r}")


@dataclass(frozen=True, eq=False)
class SyntheticScene:
    """A generated scene: ground truth (with its cameras) and the rendered views."""

    spec: SceneSpec
    truth: object
    images: tuple
    masks: tuple

    @property
    def cameras(self):
        """The true cameras, one per view."""
        return self.truth.cameras


def make_scene(spec, render=RenderSettings()):
    """Generate and render a scene with the fast renderer.

    Raises
    ------
    ValueError
        The cable would be thinner than :data:`MIN_CABLE_PIXELS` in some view.
    """
    if not 10 <= spec.views <= 60:
        raise ValueError("views must be between 10 and 60")
    truth = spec.layout()
    rig = {"orbit": orbit_cameras, "handheld": handheld_cameras}[spec.rig]
    low_views = (30.0, 60.0) if spec.kind == "hanging" else (45.0, 75.0)
    cameras = rig(truth, views=spec.views, width=spec.width, height=spec.height,
                  elevations=low_views, name_format="{:03d}." + spec.image_format,
                  seed=spec.seed)
    width = cable_pixel_width(truth, cameras)
    if width < MIN_CABLE_PIXELS:
        raise ValueError(f"the cable would be only {width:.1f} pixels wide: use a larger "
                         "radius, a smaller extent or larger images")
    truth = truth.with_cameras(cameras)
    images, masks = [], []
    for image, mask in render_views(truth, cameras, render):
        images.append(image)
        masks.append(mask)
    return SyntheticScene(spec=spec, truth=truth, images=tuple(images), masks=tuple(masks))


def write_scene(scene, folder, *, overwrite=False, jpeg_quality=92):
    """Write a scene as images, masks, a COLMAP model of the true cameras and ground truth.

    Parameters
    ----------
    scene : SyntheticScene
    folder : str or os.PathLike
        Created if missing.
    overwrite : bool, optional
        Replace a scene already written there.
    jpeg_quality : int, optional

    Returns
    -------
    pathlib.Path
    """
    folder = Path(folder)
    truth_path = folder / "ground_truth.json"
    if truth_path.exists() and not overwrite:
        raise FileExistsError(f"{folder} already holds a scene (pass overwrite to replace it)")
    (folder / "images").mkdir(parents=True, exist_ok=True)
    (folder / "masks").mkdir(exist_ok=True)
    for camera, image, mask in zip(scene.cameras, scene.images, scene.masks):
        bgr = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        options = [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality] if camera.name.endswith(".jpg") else []
        cv2.imwrite(str(folder / "images" / camera.name), bgr, options)
        cv2.imwrite(str(folder / "masks" / (Path(camera.name).stem + ".png")),
                    mask.astype(np.uint8) * 255)
    write_colmap_model(folder / "sparse", scene.cameras, overwrite=overwrite)
    write_ground_truth(scene.truth, truth_path, overwrite=overwrite)
    return folder
