"""Ground truth of a synthetic scene: the true centreline, radius, crossings and cameras.

Stored as JSON (``"format": "cable_recon.ground_truth/1"``) beside a scene's images, in the
same world units as its cameras.
"""

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .camera import Camera
from .errors import InputError
from .files import write_atomic
from .result import CablePath, Crossing, Result, StrandRef

__all__ = ["GROUND_TRUTH_FORMAT", "TrueCrossing", "GroundTruth", "read_ground_truth",
           "write_ground_truth"]

GROUND_TRUTH_FORMAT = "cable_recon.ground_truth/1"


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
    """

    centreline: np.ndarray
    radius: float
    crossings: tuple = ()
    closed: bool = False
    cameras: tuple = ()
    kind: str = "table"
    up: np.ndarray = (0.0, 0.0, 1.0)

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

    @property
    def arc_length(self):
        """Cumulative arc length at each centreline sample, starting at 0."""
        steps = np.linalg.norm(np.diff(self.centreline, axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(steps)])

    @property
    def length(self):
        """Total length of the cable (a loop includes its closing edge)."""
        closing = np.linalg.norm(self.centreline[-1] - self.centreline[0]) if self.closed else 0.0
        return float(self.arc_length[-1] + closing)

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
        return GroundTruth(self.centreline, self.radius, self.crossings, self.closed,
                           tuple(cameras), self.kind, self.up)

    def as_result(self, units="m"):
        """The truth as a perfect reconstruction result (crossings with confidence 1)."""
        crossings = tuple(Crossing(self.crossing_position(c), StrandRef(0, c.over),
                                   StrandRef(0, c.under), 1.0) for c in self.crossings)
        return Result(radius=self.radius, paths=(CablePath(self.centreline, closed=self.closed),),
                      crossings=crossings, cameras=self.cameras, units=units)

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
                       kind=str(data.get("kind", "table")), up=data.get("up", (0, 0, 1)))
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
