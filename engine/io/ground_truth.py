"""Ground truth of a synthetic scene: the true centreline, radius, crossings and cameras.

A scene may hold several cables: their centrelines follow one another in ``centreline``, each
new one starting at a sample listed in ``breaks`` (crossings index the whole array, so a
crossing between two cables is one like any other).

Stored as JSON (``"format": "cable_recon.ground_truth/1"``) beside a scene's images, in the
same world units as its cameras.
"""

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..geometry.camera import Camera
from .files import write_atomic
from .result import CablePath, Crossing, Result, StrandRef

__all__ = ["GROUND_TRUTH_FORMAT", "TrueCrossing", "GroundTruth", "read_ground_truth",
           "write_ground_truth"]

GROUND_TRUTH_FORMAT = "cable_recon.ground_truth/1"
#: Radii of arc length :attr:`GroundTruth.arc_length` puts between two cables.
_BREAK_ARC = 1000.0


@dataclass(frozen=True)
class TrueCrossing:
    """A crossing of the true cable with itself.

    Attributes
    ----------
    over, under : int
        Indices into the centreline of the upper and the lower strand's sample nearest to the
        crossing (in the table plane's projection).
    angle : float
        Angle between the two strands in the table plane, in degrees (0 < angle <= 90).
    """

    over: int
    under: int
    angle: float


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """What a synthetic scene really holds.

    Attributes
    ----------
    centreline : ndarray, shape (N, 3)
        The cable's centreline, densely sampled in order.
    radius : float
    crossings : tuple of TrueCrossing
    closed : bool
        The cable is a closed loop.
    cameras : tuple of Camera
        The true cameras of the scene's views (may be empty for a bare layout).
    kind : str
        Which generator made it (``"table"``, ``"knot"``, ``"hanging"``, ...).
    up : ndarray, shape (3,)
        The world's up direction (the table normal); "over" means higher along it.
    breaks : tuple of int
        Samples where another cable starts (empty: one cable). Several cables are open.
    """

    centreline: np.ndarray
    radius: float
    crossings: tuple = ()
    closed: bool = False
    cameras: tuple = ()
    kind: str = "table"
    up: np.ndarray = (0.0, 0.0, 1.0)
    breaks: tuple = ()

    def __post_init__(self):
        centreline = np.array(self.centreline, dtype=np.float64)
        if centreline.ndim != 2 or centreline.shape[1] != 3 or len(centreline) < 2:
            raise ValueError("centreline must be an (N, 3) array with N >= 2")
        centreline.setflags(write=False)
        up = np.array(self.up, dtype=np.float64).reshape(3)
        up /= np.linalg.norm(up)
        up.setflags(write=False)
        object.__setattr__(self, "centreline", centreline)
        object.__setattr__(self, "up", up)
        object.__setattr__(self, "radius", float(self.radius))
        object.__setattr__(self, "crossings", tuple(self.crossings))
        object.__setattr__(self, "cameras", tuple(self.cameras))
        for crossing in self.crossings:
            if not (0 <= crossing.over < len(centreline) and 0 <= crossing.under < len(centreline)):
                raise ValueError("crossing indices must point into the centreline")
        breaks = tuple(int(b) for b in self.breaks)
        bounds = (0,) + breaks + (len(centreline),)
        if any(b - a < 2 for a, b in zip(bounds, bounds[1:])):
            raise ValueError("breaks must increase and leave each cable two samples or more")
        if breaks and self.closed:
            raise ValueError("several cables are open (closed must be False with breaks)")
        object.__setattr__(self, "breaks", breaks)

    @property
    def cables(self):
        """Each cable's samples as a ``slice`` of ``centreline``, in order."""
        bounds = (0,) + self.breaks + (len(self.centreline),)
        return tuple(slice(a, b) for a, b in zip(bounds, bounds[1:]))

    @property
    def lines(self):
        """Each cable as ``(points, closed)``."""
        return tuple((self.centreline[cable], self.closed) for cable in self.cables)

    def cable_of(self, index):
        """Which cable holds centreline sample ``index``."""
        return int(np.searchsorted(self.breaks, index, side="right"))

    @property
    def arc_length(self):
        """Cumulative arc length at each centreline sample, starting at 0; a cable after a
        break starts ``_BREAK_ARC`` radii further on (arc windows never span two cables)."""
        steps = np.linalg.norm(np.diff(self.centreline, axis=0), axis=1)
        for start in self.breaks:
            steps[start - 1] = _BREAK_ARC * self.radius
        return np.concatenate([[0.0], np.cumsum(steps)])

    @property
    def length(self):
        """Total length of the cables (a loop includes its closing edge)."""
        closing = np.linalg.norm(self.centreline[-1] - self.centreline[0]) if self.closed else 0.0
        return float(self.arc_length[-1] - len(self.breaks) * _BREAK_ARC * self.radius
                     + closing)

    def crossing_position(self, crossing):
        """Midpoint of the two strands at ``crossing``."""
        return 0.5 * (self.centreline[crossing.over] + self.centreline[crossing.under])

    def crossing_in_view(self, crossing, camera, *, reach=4.0):
        """Where the two strands of ``crossing`` meet in ``camera``'s image.

        The projected 3D midpoint is not where a view sees the strands cross: the upper strand
        lies 2 r higher, so in an oblique view its image slides along the lower one. This is
        the point where the two projected centrelines come closest, within ``reach`` radii of
        arc length of the crossing on each strand.

        Returns
        -------
        pixel : ndarray, shape (2,)
            COLMAP image coordinates (NaN if the crossing is behind the camera).
        depth : float
        """
        arc = self.arc_length
        strands = []
        for index in (crossing.over, crossing.under):
            near = np.abs(arc - arc[index]) <= reach * self.radius
            pixels, depths = camera.project(self.centreline[near])
            strands.append((pixels, depths))
        (over, over_depth), (under, under_depth) = strands
        if not (np.all(over_depth > 0) and np.all(under_depth > 0)):
            return np.full(2, np.nan), float("nan")
        distance = np.linalg.norm(over[:, None, :] - under[None, :, :], axis=2)
        i, j = np.unravel_index(np.argmin(distance), distance.shape)
        return 0.5 * (over[i] + under[j]), float(0.5 * (over_depth[i] + under_depth[j]))

    def with_cameras(self, cameras):
        """A copy with ``cameras`` as the scene's views."""
        return replace(self, cameras=tuple(cameras))

    def strand_ref(self, index):
        """Sample ``index`` as a :class:`engine.io.result.StrandRef` (one path per cable)."""
        cable = self.cable_of(index)
        return StrandRef(cable, index - self.cables[cable].start)

    def as_result(self, units="m"):
        """The truth as a perfect reconstruction result (crossings with confidence 1)."""
        crossings = tuple(Crossing(self.crossing_position(c), self.strand_ref(c.over),
                                   self.strand_ref(c.under), 1.0) for c in self.crossings)
        paths = tuple(CablePath(points, closed=closed) for points, closed in self.lines)
        return Result(radius=self.radius, paths=paths, crossings=crossings,
                      cameras=self.cameras, units=units)

    def to_dict(self):
        """JSON-ready dict in ``cable_recon.ground_truth/1``."""
        return {
            "format": GROUND_TRUTH_FORMAT,
            "kind": self.kind,
            "radius": self.radius,
            "closed": self.closed,
            "up": self.up.tolist(),
            "centreline": self.centreline.tolist(),
            "crossings": [{"over": c.over, "under": c.under, "angle": c.angle}
                          for c in self.crossings],
            "cameras": [camera.to_dict() for camera in self.cameras],
            **({"breaks": list(self.breaks)} if self.breaks else {}),
        }

    @classmethod
    def from_dict(cls, data):
        """Build from :meth:`to_dict` output; :class:`InputError` on a malformed document."""
        if not isinstance(data, dict) or data.get("format") != GROUND_TRUTH_FORMAT:
            raise InputError(f"not a {GROUND_TRUTH_FORMAT} document")
        try:
            crossings = tuple(TrueCrossing(int(c["over"]), int(c["under"]), float(c["angle"]))
                              for c in data.get("crossings", []))
            cameras = tuple(Camera.from_dict(c) for c in data.get("cameras", []))
            return cls(centreline=np.asarray(data["centreline"], dtype=np.float64),
                       radius=float(data["radius"]), crossings=crossings,
                       closed=bool(data.get("closed", False)), cameras=cameras,
                       kind=str(data.get("kind", "table")), up=data.get("up", (0, 0, 1)),
                       breaks=tuple(int(b) for b in data.get("breaks", ())))
        except (KeyError, TypeError, ValueError) as error:
            raise InputError(f"malformed ground truth: {error}") from None


def read_ground_truth(path):
    """Read a ground-truth JSON file."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as error:
        raise InputError(f"{path}: cannot be read ({error})") from None
    try:
        return GroundTruth.from_dict(data)
    except InputError as error:
        raise InputError(f"{path}: {error}") from None


def write_ground_truth(truth, path, *, overwrite=False):
    """Write a ground-truth JSON file atomically."""
    return write_atomic(path, json.dumps(truth.to_dict(), indent=1) + "\n", overwrite=overwrite)
