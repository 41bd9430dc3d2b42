"""Camera estimation with pycolmap (paper §3.2): poses and shared intrinsics from the photos.

The pipeline, all in pycolmap:

1. SIFT features on the full-size images (``first_octave`` 0, at most ``max_features`` per
   image), all frames sharing ONE camera (one set of intrinsics, as from one phone or video);
2. sequential matching in the caller's (video) order: each frame with the next
   ``sequential_overlap`` frames and, with ``quadratic_overlap``, frames 1, 2, 4, 8, ... ahead;
3. incremental mapping (largest model kept); if too few frames register, exhaustive matching
   adds the missing pairs and mapping runs again;
4. the world is made upright (:mod:`engine.geometry.upright`): the table is z = 0, +z up,
   scale unchanged.

The pairs for step 2 are generated here and matched with ``pycolmap.match_image_pairs``, because
``pycolmap.match_sequential`` orders frames by name, which is not video order for names like
``frame2`` / ``frame10``. Features and matches are computed in small batches so that progress can
be reported and a cancel request is honoured within about a second.

Determinism: with a fixed ``seed`` and ``deterministic`` on (the default) the cameras are
bit-identical run to run: pycolmap's global seed and every RANSAC and mapper seed are set, images
get fixed ids before extraction, and matching and mapping run on one thread (see
:class:`CameraEstimationSettings`).
"""

import contextlib
import logging
import math
import os
import shutil
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import Cancelled, InputError, ReconstructionError
from ..geometry.camera import CAMERA_MODELS, Camera
from ..geometry.similarity import Similarity
from ..geometry.upright import UprightSettings, make_upright
from ..io.colmap import natural_key
from ..progress import StageProgress, check_cancel
from ..settings import check_settings, setting

__all__ = ["CameraEstimationSettings", "CameraEstimate", "estimate_cameras"]

log = logging.getLogger(__name__)

_DATABASE = "database.db"
_PAIRS = "pairs.txt"
_SPARSE = "sparse"
#: Matches computed per pycolmap call (progress and cancel granularity).
_PAIRS_PER_BATCH = 48


@dataclass(frozen=True)
class CameraEstimationSettings:
    """Tunables of :func:`estimate_cameras`; the single source of their defaults.

    Attributes
    ----------
    max_features : int
        SIFT features kept per image. With ``first_octave`` 0, 2048 registers every view of
        the synthetic scenes and the rendered sample (``python -m engine bench cameras``).
    first_octave : int
        SIFT's first octave: 0 works on the full-size image; COLMAP's -1 first doubles its
        size (four times the pixels to search).
    max_image_size : int
        Larger images are downscaled to this many pixels on their long side for SIFT.
    camera_model : str
        COLMAP model of the one shared camera: ``"SIMPLE_RADIAL"`` (f, cx, cy, k; robust with
        few views of a flat scene) or ``"OPENCV"`` (fx, fy, cx, cy, k1, k2, p1, p2; for strong
        lens distortion), or any other key of :data:`~engine.geometry.camera.CAMERA_MODELS`.
    sequential_overlap : int
        Each frame is matched with this many following frames (COLMAP's default is 10).
    quadratic_overlap : bool
        Also match each frame with the frames 2, 4, 8, ... (up to ``2**(overlap-1)``) ahead.
    exhaustive_below : float
        If sequential matching registers fewer than this share of the frames, every remaining
        pair is matched too (exhaustive matching) and mapping runs again; 0 never does.
    exhaustive_max_frames : int
        No exhaustive matching for more frames than this (its cost grows with the square of
        the frames: about 10 ms per pair at 960x720, 2 minutes for 150 frames).
    min_registered : int
        Fewer registered frames than ``max(min_registered, min_registered_share * frames)`` is
        a failure (:class:`~.errors.ReconstructionError`).
    min_registered_share : float
        See ``min_registered``.
    upright : bool
        Make the world upright (table plane z = 0, +z up); otherwise keep COLMAP's frame.
    seed : int
        Seed of pycolmap's random sampling.
    num_threads : int
        Threads pycolmap may use; 0 or -1 use every core.
    deterministic : bool
        Match image pairs and map on one thread (features still use ``num_threads``), so a
        given seed gives bit-identical cameras run after run (``tests/test_camera_estimation.py``
        runs it twice); with threads a run can differ by a few inlier matches, and moves its
        cameras a little.
    """

    max_features: int = setting(2048, low=1)
    first_octave: int = setting(0, low=-1)
    max_image_size: int = setting(3200, low=1, unit="px")
    camera_model: str = "SIMPLE_RADIAL"
    sequential_overlap: int = setting(5, low=1, unit="frames")
    quadratic_overlap: bool = True
    exhaustive_below: float = setting(0.9, low=0, high=1)
    exhaustive_max_frames: int = setting(150, low=1, unit="frames")
    min_registered: int = setting(3, low=1, unit="frames")
    min_registered_share: float = setting(0.5, low=0, high=1)
    upright: bool = True
    seed: int = setting(0, low=0)
    num_threads: int = setting(-1, low=-1)
    deterministic: bool = True

    def __post_init__(self):
        check_settings(self)
        if self.camera_model not in CAMERA_MODELS:
            raise ValueError(f"camera_model must be one of {', '.join(CAMERA_MODELS)}, "
                             f"not {self.camera_model!r}")

    def threads(self):
        """pycolmap's ``num_threads``: -1 (every core) for 0 or -1."""
        return -1 if self.num_threads <= 0 else int(self.num_threads)

    def required_registered(self, frames):
        """How many of ``frames`` frames must register for the estimate to succeed."""
        return max(int(self.min_registered), math.ceil(self.min_registered_share * frames))


@dataclass(frozen=True, eq=False)
class CameraEstimate:
    """Cameras estimated from photos, in an upright world frame (see
    :mod:`engine.geometry.upright`).

    Attributes
    ----------
    cameras : tuple of Camera
        The registered frames, in natural order of their names (file names), one shared set
        of intrinsics.
    points : ndarray, shape (M, 3)
        Sparse 3D points, float64, in the same frame.
    unregistered : tuple of str
        Names of the frames that did not register, in the input order.
    transform : Similarity
        The move applied to COLMAP's frame to make it upright (scale 1; identity when
        ``upright`` is off).
    plane_found : bool
        The table plane was found (False: the cameras' up direction set +z, or no upright).
    reprojection_error : float
        Mean reprojection error of the sparse points, pixels (from pycolmap).
    matching : str
        ``"sequential"`` or ``"exhaustive"`` (the fallback ran).
    """

    cameras: tuple
    points: np.ndarray
    unregistered: tuple
    transform: Similarity
    plane_found: bool
    reprojection_error: float = float("nan")
    matching: str = "sequential"

    @property
    def names(self):
        """Names of the registered frames."""
        return tuple(camera.name for camera in self.cameras)


# -- plumbing ------------------------------------------------------------------------------------

def _check(cancel):
    check_cancel(cancel, "camera estimation")


@contextlib.contextmanager
def _colmap_call(cancel, token):
    """Run pycolmap quietly and turn its cancellation into :class:`Cancelled`.

    A watcher thread forwards ``cancel`` to pycolmap's cancellation token, which pycolmap checks
    between images, matching blocks and mapping steps.
    """
    import pycolmap

    _check(cancel)
    stop = threading.Event()
    watcher = None
    if cancel is not None:
        def watch():
            while not stop.is_set():
                if cancel.is_set():
                    token.cancel()
                    return
                stop.wait(0.05)

        watcher = threading.Thread(target=watch, name="colmap-cancel", daemon=True)
        watcher.start()
    level = pycolmap.logging.minloglevel
    # COLMAP logs every step (and its own failures, which we report) to stderr: keep it quiet.
    pycolmap.logging.minloglevel = max(level, int(pycolmap.logging.FATAL))
    try:
        yield
    except InterruptedError:
        if cancel is not None and cancel.is_set():
            raise Cancelled("camera estimation was cancelled") from None
        raise
    finally:
        pycolmap.logging.minloglevel = level
        stop.set()
        if watcher is not None:
            watcher.join()
    _check(cancel)


def _abbreviate(names, limit=6):
    names = list(names)
    if len(names) <= limit:
        return ", ".join(names)
    return f"{', '.join(names[:limit])} and {len(names) - limit} more"


def _sequential_pairs(count, overlap, quadratic):
    """Index pairs ``(i, j)``, ``i < j``: each frame with the next frames (COLMAP's scheme)."""
    pairs = set()
    for i in range(count):
        for k in range(1, overlap + 1):
            if i + k < count:
                pairs.add((i, i + k))
        if quadratic:
            for k in range(overlap):
                if i + 2 ** k < count:
                    pairs.add((i, i + 2 ** k))
    return sorted(pairs)


def _stage_images(paths, work):
    """A folder holding every image under its file name, the names in input order, and the
    staging folder made for that (None if the images already share one folder)."""
    names = [path.name for path in paths]
    if len(set(names)) != len(names):
        duplicates = sorted({name for name in names if names.count(name) > 1})
        raise InputError(f"image file names must be unique; repeated: {_abbreviate(duplicates)}")
    parents = {path.parent.resolve() for path in paths}
    if len(parents) == 1:
        return parents.pop(), names, None
    folder = Path(tempfile.mkdtemp(prefix="images_", dir=work))
    for path in paths:
        target = folder / path.name
        try:
            os.symlink(path.resolve(), target)
        except OSError:  # no symlinks (Windows without the privilege): copy
            shutil.copy2(path, target)
    return folder, names, folder


def _prior_params(model, focal, width, height):
    cx, cy = width / 2.0, height / 2.0
    extra = len(CAMERA_MODELS[model]) - (4 if model in ("PINHOLE", "OPENCV") else 3)
    head = [focal, focal, cx, cy] if model in ("PINHOLE", "OPENCV") else [focal, cx, cy]
    return np.array(head + [0.0] * extra, dtype=np.float64)


def _extract(database, folder, names, settings, focal_length_px, token, cancel, stage):
    import pycolmap

    options = pycolmap.FeatureExtractionOptions()
    options.max_image_size = int(settings.max_image_size)
    options.num_threads = settings.threads()
    options.sift.max_num_features = int(settings.max_features)
    options.sift.first_octave = int(settings.first_octave)
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = settings.camera_model
    stage(0.0, f"features: reading {len(names)} images")
    # Importing first gives every image a fixed id (COLMAP numbers them by name) and makes the
    # one shared camera (id 1): batched multi-threaded extraction would number images in the
    # order threads finish them, and the mapping would then differ from run to run.
    pycolmap.Database.open(database).close()
    with _colmap_call(cancel, token):
        pycolmap.import_images(database, folder, camera_mode=pycolmap.CameraMode.SINGLE,
                               image_names=names, options=reader)
    reader.existing_camera_id = 1
    if focal_length_px is not None:
        db = pycolmap.Database.open(database)
        try:
            camera = db.read_camera(1)
            camera.params = _prior_params(settings.camera_model, float(focal_length_px),
                                          camera.width, camera.height)
            camera.has_prior_focal_length = True
            db.update_camera(camera)
        finally:
            db.close()
    # a few images a call: each call's fixed cost is shared, and a cancel is seen between calls
    batch = max(8, 4 * (os.cpu_count() or 1))
    for start in range(0, len(names), batch):
        stage(0.05 + 0.95 * start / len(names), f"features: image {start + 1} of {len(names)}")
        with _colmap_call(cancel, token):
            pycolmap.extract_features(
                database, folder, image_names=names[start:start + batch],
                camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader,
                extraction_options=options, device=pycolmap.Device.cpu,
                cancellation_token=token)
    stage(1.0, f"features: {len(names)} images")


def _match(database, work, names, pairs, settings, token, cancel, stage, label):
    import pycolmap

    matching = pycolmap.FeatureMatchingOptions()
    # Multi-threaded matching verifies pairs in whatever order threads take them, which now
    # and then changes a few inlier matches (seeded RANSAC notwithstanding).
    matching.num_threads = 1 if settings.deterministic else settings.threads()
    verification = pycolmap.TwoViewGeometryOptions()
    verification.ransac.random_seed = int(settings.seed)
    pair_file = work / _PAIRS
    for start in range(0, len(pairs), _PAIRS_PER_BATCH):
        stage(start / max(len(pairs), 1), f"{label} matching: pair {start + 1} of {len(pairs)}")
        batch = pairs[start:start + _PAIRS_PER_BATCH]
        pair_file.write_text("".join(f"{names[i]} {names[j]}\n" for i, j in batch),
                             encoding="utf-8")
        with _colmap_call(cancel, token):
            pycolmap.match_image_pairs(
                database, matching_options=matching,
                pairing_options=pycolmap.ImportedPairingOptions(match_list_path=str(pair_file)),
                verification_options=verification, device=pycolmap.Device.cpu,
                cancellation_token=token)
    stage(1.0, f"{label} matching: {len(pairs)} pairs")


def _map(database, folder, work, total, settings, token, cancel, stage, attempt):
    """Incremental mapping; the largest reconstruction, or None."""
    import pycolmap

    options = pycolmap.IncrementalPipelineOptions()
    # Multi-threaded mapping, too, now and then ends a few ulps apart, which then grow.
    options.num_threads = 1 if settings.deterministic else settings.threads()
    options.random_seed = int(settings.seed)
    options.mapper.random_seed = int(settings.seed)
    options.triangulation.random_seed = int(settings.seed)
    options.min_model_size = int(settings.min_registered)
    options.extract_colors = False
    output = work / _SPARSE / attempt
    output.mkdir(parents=True, exist_ok=True)
    registered = [0]

    def initial_pair():
        registered[0] = 2
        stage(registered[0] / total, f"mapping: {registered[0]} of {total} frames")

    def next_image():
        registered[0] += 1
        stage(registered[0] / total, f"mapping: {registered[0]} of {total} frames")

    stage(0.0, "mapping")
    with _colmap_call(cancel, token):
        models = pycolmap.incremental_mapping(database, folder, output, options=options,
                                              initial_image_pair_callback=initial_pair,
                                              next_image_callback=next_image,
                                              cancellation_token=token)
    if not models:
        return None
    best = max(models.values(), key=lambda model: (model.num_reg_images(),
                                                   model.num_points3D()))
    log.info("mapping: %d model(s), largest registers %d of %d frames", len(models),
             best.num_reg_images(), total)
    return best


def _to_engine(reconstruction):
    cameras = []
    for image in reconstruction.images.values():
        if not image.has_pose:
            continue
        intrinsics = reconstruction.cameras[image.camera_id]
        pose = image.cam_from_world().matrix()
        cameras.append(Camera(name=image.name, width=intrinsics.width, height=intrinsics.height,
                              model=intrinsics.model.name, params=np.array(intrinsics.params),
                              R=pose[:, :3], t=pose[:, 3]))
    cameras.sort(key=lambda camera: natural_key(camera.name))
    points = np.array([point.xyz for point in reconstruction.points3D.values()],
                      dtype=np.float64).reshape(-1, 3)
    return tuple(cameras), points


# -- public API ----------------------------------------------------------------------------------

def estimate_cameras(image_paths, *, settings=CameraEstimationSettings(), focal_length_px=None,
                     progress=None, cancel=None, work_dir=None, upright=UprightSettings()):
    """Estimate one shared camera and a pose per frame with pycolmap, in an upright frame.

    Parameters
    ----------
    image_paths : sequence of str or os.PathLike
        Image files of one capture, all the same size (already validated), in video order
        (sequential matching pairs neighbours in this order). File names must be unique; they
        name the cameras.
    settings : CameraEstimationSettings, optional
    upright : UprightSettings, optional
        How the table plane is found, when ``settings.upright`` puts the world upright.
    focal_length_px : float, optional
        Prior focal length in pixels (e.g. from EXIF); refined by bundle adjustment. Without
        it COLMAP starts from 1.2 times the longer image side.
    progress : callable, optional
        ``progress(fraction, message)``, called from this thread at stage boundaries and per
        batch of images or pairs and per registered frame.
    cancel : threading.Event, optional
        When set, the work stops within about a second and :class:`~.errors.Cancelled` is
        raised.
    work_dir : str or os.PathLike, optional
        Folder for COLMAP's database and models, kept afterwards (``database.db``,
        ``pairs.txt``, ``sparse/sequential/0``, ...; a database already there is replaced,
        nothing else is deleted). Without it a temporary folder is used and removed.

    Returns
    -------
    CameraEstimate

    Raises
    ------
    InputError
        No images, fewer images than ``settings.min_registered``, a missing file, or repeated
        file names.
    ReconstructionError
        Fewer frames registered than :meth:`CameraEstimationSettings.required_registered`;
        the message names frames that did not register.
    Cancelled
        ``cancel`` was set.
    """
    import pycolmap

    paths = [Path(path) for path in image_paths]
    if not paths:
        raise InputError("camera estimation needs images, got none")
    if len(paths) < settings.min_registered:
        raise InputError(f"camera estimation needs at least {settings.min_registered} images, "
                         f"got {len(paths)}")
    missing = [str(path) for path in paths if not path.is_file()]
    if missing:
        raise InputError(f"image file not found: {_abbreviate(missing, 3)}")
    if focal_length_px is not None and not (np.isfinite(focal_length_px)
                                            and focal_length_px > 0):
        raise ValueError(f"focal_length_px must be a positive number, not {focal_length_px!r}")
    _check(cancel)

    with contextlib.ExitStack() as stack:
        if work_dir is None:
            work = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="cameras_")))
        else:
            work = Path(work_dir)
            work.mkdir(parents=True, exist_ok=True)
            for stale in (work / _DATABASE, work / f"{_DATABASE}-wal", work / f"{_DATABASE}-shm"):
                stale.unlink(missing_ok=True)
        folder, names, staged = _stage_images(paths, work)
        if staged is not None:
            stack.callback(shutil.rmtree, staged, ignore_errors=True)
        return _estimate(folder, names, work, settings, upright, focal_length_px, progress,
                         cancel, pycolmap)


def _reconstruct(folder, names, work, settings, focal_length_px, progress, cancel, pycolmap):
    """pycolmap's best reconstruction of the frames (None if none), the matching that made it
    ("sequential", or "exhaustive" when the sequential pairs registered too few frames) and the
    seconds each step took."""
    database = work / _DATABASE
    total = len(names)
    token = pycolmap.CancellationToken()
    pycolmap.set_random_seed(int(settings.seed))
    timings = {}

    clock = time.perf_counter()
    _extract(database, folder, names, settings, focal_length_px, token, cancel,
             StageProgress(progress, 0.0, 0.4))
    timings["features"] = time.perf_counter() - clock

    clock = time.perf_counter()
    sequential = _sequential_pairs(total, int(settings.sequential_overlap),
                                   bool(settings.quadratic_overlap))
    _match(database, work, names, sequential, settings, token, cancel,
           StageProgress(progress, 0.4, 0.55), "sequential")
    timings["matching"] = time.perf_counter() - clock

    clock = time.perf_counter()
    best = _map(database, folder, work, total, settings, token, cancel,
                StageProgress(progress, 0.55, 0.8), "sequential")
    timings["mapping"] = time.perf_counter() - clock
    matching = "sequential"
    registered = 0 if best is None else best.num_reg_images()
    if (registered < settings.exhaustive_below * total
            and total <= settings.exhaustive_max_frames):
        log.info("sequential matching registered %d of %d frames: matching every pair",
                 registered, total)
        clock = time.perf_counter()
        done = set(sequential)
        rest = [(i, j) for i in range(total) for j in range(i + 1, total) if (i, j) not in done]
        _match(database, work, names, rest, settings, token, cancel,
               StageProgress(progress, 0.8, 0.88), "exhaustive")
        pycolmap.set_random_seed(int(settings.seed))
        again = _map(database, folder, work, total, settings, token, cancel,
                     StageProgress(progress, 0.88, 0.97), "exhaustive")
        timings["exhaustive"] = time.perf_counter() - clock
        if again is not None and again.num_reg_images() > registered:
            best, registered, matching = again, again.num_reg_images(), "exhaustive"
    return best, matching, timings


def _estimate(folder, names, work, settings, upright, focal_length_px, progress, cancel,
              pycolmap):
    """Features, matching and mapping of the frames ``names`` in ``folder``, then the cameras
    checked (enough registered) and made upright: a :class:`CameraEstimate`."""
    best, matching, timings = _reconstruct(folder, names, work, settings, focal_length_px,
                                           progress, cancel, pycolmap)
    total = len(names)
    if best is None:
        cameras, points = (), np.zeros((0, 3))
    else:
        cameras, points = _to_engine(best)
    done_names = {camera.name for camera in cameras}
    unregistered = tuple(name for name in names if name not in done_names)
    required = settings.required_registered(total)
    log.info("cameras: %d of %d frames registered (%s matching), %d sparse points; %s",
             len(cameras), total, matching, len(points),
             ", ".join(f"{key} {value:.1f} s" for key, value in timings.items()))
    if len(cameras) < required:
        raise ReconstructionError(
            f"camera estimation failed: only {len(cameras)} of {total} frames registered "
            f"(need {required}); not registered: {_abbreviate(unregistered)}")
    if unregistered:
        log.warning("%d of %d frames did not register: %s", len(unregistered), total,
                    _abbreviate(unregistered))

    error = float(best.compute_mean_reprojection_error())
    if settings.upright:
        _check(cancel)
        cameras, points, transform, plane_found = make_upright(
            cameras, points, settings=upright)
    else:
        transform = Similarity(1.0, np.eye(3), np.zeros(3))
        plane_found = False
    if progress is not None:
        progress(1.0, f"cameras: {len(cameras)} of {total} frames registered")
    return CameraEstimate(cameras=tuple(cameras), points=np.asarray(points, dtype=np.float64),
                          unregistered=unregistered, transform=transform,
                          plane_found=bool(plane_found), reprojection_error=error,
                          matching=matching)
