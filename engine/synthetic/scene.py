"""Synthetic scenes: a layout, cameras around it, and its views, kept or written to disk.

A written scene is a folder a user's capture would look like, plus what is really there::

    images/000.png ...      colour views (000.jpg ... when the look compresses them)
    masks/000.png ...       exact cable masks (cable = 255), same stems
    sparse/                 COLMAP text model of the true cameras
    ground_truth.json       cable_recon.ground_truth/1
    look.json               the look's fields (engine.synthetic.looks.Look)

A scene is drawn in a *look* (:mod:`engine.synthetic.looks`): :func:`look_scene` builds "family X,
seed N" in one call.
"""

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..io.colmap import write_colmap_model
from ..io.ground_truth import write_ground_truth
from .cameras import cable_pixel_width, handheld_cameras, orbit_cameras
from .layouts import (hanging_layout, hard_layout, knot_layout, pair_layout,
                      table_layout)
from .looks import DEFAULT_LOOK, SEVERAL_CABLES, ClutterObject, Look, sample_look
from .render import render_views

__all__ = ["SceneSpec", "SyntheticScene", "make_scene", "write_scene", "look_spec", "look_scene",
           "lift_truth", "read_look", "render_scene_to", "hard_spec", "HARD_FRAMING",
           "MIN_CABLE_PIXELS"]

#: Nothing can be reconstructed from a thinner wire; scenes are always at least this wide.
MIN_CABLE_PIXELS = 5.0


@dataclass(frozen=True)
class SceneSpec:
    """What to generate.

    Attributes
    ----------
    kind : str
        ``"table"``, ``"loop"`` (a closed cable on the table), ``"knot"``, ``"hanging"``,
        ``"pair"`` (two cables crossing each other) or ``"hard"`` (a heap: 12 to 20
        crossings close together, :func:`engine.synthetic.layouts.hard_layout`).
    crossings : int
        For ``"table"``, ``"loop"`` and ``"pair"``.
    seed : int
    radius : float
        Metres.
    extent : float or None
        Metres; derived from the radius and crossings if None.
    views : int
    rig : str
        ``"orbit"`` or ``"handheld"``.
    framing : float
        The share of the cable's extent a view frames
        (:func:`engine.synthetic.cameras.orbit_cameras`): 1 shows the whole cable in every view;
        under 1 the cameras come closer and aim around it, so each part of the cable is out of some
        frames (:func:`engine.synthetic.cameras.out_of_frame`).
    width, height : int
        Image size.
    image_format : str or None
        ``"png"`` or ``"jpg"``; None: ``"jpg"`` when the look compresses its frames
        (``look.jpeg_quality < 100``), else ``"png"``.
    look : Look
        What the scene looks like (:mod:`engine.synthetic.looks`); its ``lift`` raises the layout.
    """

    kind: str = "table"
    crossings: int = 3
    seed: int = 0
    radius: float = 0.004
    extent: float = None
    views: int = 30
    rig: str = "orbit"
    framing: float = 1.0
    width: int = 960
    height: int = 720
    image_format: str = None
    look: Look = DEFAULT_LOOK

    def __post_init__(self):
        if self.image_format not in (None, "png", "jpg"):
            raise ValueError("image_format must be 'png', 'jpg' or None")
        if not isinstance(self.look, Look):
            raise ValueError("look must be a Look (see engine.synthetic.looks)")

    @property
    def file_format(self):
        """The image files' format: ``image_format``, or the look's choice if that is None."""
        if self.image_format is not None:
            return self.image_format
        return "jpg" if self.look.jpeg_quality < 100 else "png"

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
        if self.kind == "pair":
            return pair_layout(self.crossings, **common)
        if self.kind == "hard":
            return hard_layout(**common)
        raise ValueError(f"unknown scene kind {self.kind!r}")


@dataclass(frozen=True, eq=False)
class SyntheticScene:
    """A generated scene: ground truth (with its cameras) and the rendered views.

    ``encoded`` holds each view's JPEG file when the look compresses its frames (``images``
    are those files decoded), so a written scene holds exactly the images kept in memory.
    """

    spec: SceneSpec
    truth: object
    images: tuple
    masks: tuple
    encoded: tuple = ()

    @property
    def cameras(self):
        """The true cameras, one per view."""
        return self.truth.cameras


def lift_truth(truth, lift):
    """The truth raised ``lift`` radii above the table (crossings and cameras kept)."""
    if not lift:
        return truth
    centreline = truth.centreline + np.array([0.0, 0.0, lift * truth.radius])
    return dataclasses.replace(truth, centreline=centreline)


def make_scene(spec, *, texture=None):
    """Generate and render a scene in its look with the fast renderer.

    The layout is raised by ``spec.look.lift`` radii (the ground truth with it), then framed
    by the cameras.

    Parameters
    ----------
    spec : SceneSpec
    texture : ndarray, optional
        Table texture to use instead of the look's (RGB uint8, square).

    Raises
    ------
    ValueError
        The cable would be thinner than :data:`MIN_CABLE_PIXELS` in some view.
    """
    truth = _framed_truth(spec)
    images, masks, encoded = [], [], []
    for image, mask, data in render_views(truth, truth.cameras, spec.look, texture=texture,
                                          encoded=True):
        images.append(image)
        masks.append(mask)
        encoded.append(data)
    return SyntheticScene(spec=spec, truth=truth, images=tuple(images), masks=tuple(masks),
                          encoded=tuple(encoded) if spec.look.jpeg_quality < 100 else ())


def _framed_truth(spec):
    """The spec's ground truth, lifted by its look, with the cameras of its rig."""
    if not 3 <= spec.views <= 400:
        raise ValueError("views must be between 3 and 400")
    truth = lift_truth(spec.layout(), spec.look.lift)
    rig = {"orbit": orbit_cameras, "handheld": handheld_cameras}[spec.rig]
    low_views = (30.0, 60.0) if spec.kind == "hanging" else (45.0, 75.0)
    cameras = rig(truth, views=spec.views, width=spec.width, height=spec.height,
                  elevations=low_views, name_format="{:03d}." + spec.file_format,
                  seed=spec.seed, framing=spec.framing)
    width = cable_pixel_width(truth, cameras)
    if width < MIN_CABLE_PIXELS:
        raise ValueError(f"the cable would be only {width:.1f} pixels wide: use a larger "
                         "radius, a smaller extent or larger images")
    return truth.with_cameras(cameras)


#: How much of a hard scene each view frames (:attr:`SceneSpec.framing`): a centreline point
#: of a hard layout is out of 15–45% of 30 orbit views on average and out of fewer than 80% at
#: most (:func:`engine.synthetic.cameras.out_of_frame`;
#: ``test_views_that_frame_part_of_the_cable``).
HARD_FRAMING = 0.6


def hard_spec(seed, *, views=30, width=960, height=720, framing=HARD_FRAMING, **fields):
    """The hard scene of ``seed``: a heap (:func:`engine.synthetic.layouts.hard_layout`) in the
    default look, seen by views that each frame part of it (``framing``).

    Returns
    -------
    SceneSpec
    """
    return SceneSpec(kind="hard", seed=seed, views=views, width=width, height=height,
                     framing=framing, **fields)


def look_spec(family, seed, *, kind=None, crossings=3, views=24, width=640, height=480,
              **fields):
    """The scene "look ``family``, seed ``seed``": its look and its layout drawn from the seed.

    Parameters
    ----------
    family : str
        One of :data:`engine.synthetic.looks.LOOK_FAMILIES`, or ``"default"`` (the original look).
    seed : int
        Seeds the look (:func:`engine.synthetic.looks.sample_look`) and the layout.
    kind, crossings, views, width, height
        As :class:`SceneSpec`; ``kind`` None: ``"pair"`` for a family of several cables
        (:data:`engine.synthetic.looks.SEVERAL_CABLES`), else ``"table"``.
    **fields
        Further :class:`SceneSpec` fields (``radius``, ``rig``, ``image_format``, ...).

    Returns
    -------
    SceneSpec
    """
    look = DEFAULT_LOOK if family == "default" else sample_look(family, seed)
    if kind is None:
        kind = "pair" if family in SEVERAL_CABLES else "table"
    return SceneSpec(kind=kind, crossings=crossings, seed=seed, views=views, width=width,
                     height=height, look=look, **fields)


def look_scene(family, seed, *, kind=None, crossings=3, views=24, width=640, height=480,
               **fields):
    """Build and render the scene of :func:`look_spec` in one call.

    Returns
    -------
    SyntheticScene
    """
    return make_scene(look_spec(family, seed, kind=kind, crossings=crossings, views=views,
                                width=width, height=height, **fields))


def write_scene(scene, folder, *, overwrite=False, jpeg_quality=92):
    """Write a scene as images, masks, a COLMAP model of the true cameras, ground truth and
    its look.

    A look that compresses its frames has them written as the very JPEG files they were
    decoded from, so the images on disk are the images in memory.

    Parameters
    ----------
    scene : SyntheticScene
    folder : str or os.PathLike
        Created if missing.
    overwrite : bool, optional
        Replace a scene already written there.
    jpeg_quality : int, optional
        For JPEG files of a look that does not compress its frames.

    Returns
    -------
    pathlib.Path
    """
    folder = _scene_folder(folder, overwrite)
    encoded = scene.encoded or (None,) * len(scene.images)
    for camera, image, mask, data in zip(scene.cameras, scene.images, scene.masks, encoded):
        _write_view(folder, camera, image, mask, data, jpeg_quality)
    return _write_truth(folder, scene.truth, scene.spec.look, overwrite)


def render_scene_to(spec, folder, *, overwrite=False):
    """Render a scene and write it view by view, as :func:`write_scene` lays it out, holding
    one view at a time (for captures too large to keep in memory: 200 views of 4K are 5 GB).

    Parameters
    ----------
    spec : SceneSpec
    folder : str or os.PathLike
    overwrite : bool, optional

    Returns
    -------
    pathlib.Path
    """
    folder = _scene_folder(folder, overwrite)
    truth = _framed_truth(spec)
    for camera, (image, mask, data) in zip(truth.cameras, render_views(
            truth, truth.cameras, spec.look, encoded=True)):
        _write_view(folder, camera, image, mask, data, 92)
    return _write_truth(folder, truth, spec.look, overwrite)


def _scene_folder(folder, overwrite):
    folder = Path(folder)
    if (folder / "ground_truth.json").exists() and not overwrite:
        raise FileExistsError(f"{folder} already holds a scene (pass overwrite to replace it)")
    (folder / "images").mkdir(parents=True, exist_ok=True)
    (folder / "masks").mkdir(exist_ok=True)
    return folder


def _write_view(folder, camera, image, mask, data, jpeg_quality):
    path = folder / "images" / camera.name
    if data is not None and camera.name.endswith(".jpg"):
        path.write_bytes(data)
    else:
        bgr = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        options = [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality] if camera.name.endswith(".jpg") \
            else []
        cv2.imwrite(str(path), bgr, options)
    cv2.imwrite(str(folder / "masks" / (Path(camera.name).stem + ".png")),
                mask.astype(np.uint8) * 255)


def _write_truth(folder, truth, look, overwrite):
    """The scene's COLMAP model of the true cameras, ground truth and look."""
    write_colmap_model(folder / "sparse", truth.cameras, overwrite=overwrite)
    write_ground_truth(truth, folder / "ground_truth.json", overwrite=overwrite)
    (folder / "look.json").write_text(
        json.dumps(dataclasses.asdict(look), indent=1) + "\n", encoding="utf-8")
    return folder


def read_look(path):
    """The look a written scene was drawn in (its ``look.json``).

    Parameters
    ----------
    path : str or os.PathLike
        The ``look.json`` file, or the scene's folder.

    Returns
    -------
    Look
    """
    path = Path(path)
    if path.is_dir():
        path = path / "look.json"
    data = json.loads(path.read_text(encoding="utf-8"))
    fields = {f.name for f in dataclasses.fields(Look)}
    unknown = set(data) - fields
    if unknown:
        raise ValueError(f"{path}: unknown look fields {sorted(unknown)}")
    data = {key: tuple(value) if isinstance(value, list) else value
            for key, value in data.items()}
    data["clutter"] = tuple(ClutterObject(**{k: tuple(v) if isinstance(v, list) else v
                                             for k, v in thing.items()})
                            for thing in data.get("clutter", ()))
    return Look(**data)
