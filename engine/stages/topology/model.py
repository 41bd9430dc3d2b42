"""What the topology stage takes and gives: views, paths, crossings and the whole topology."""

from dataclasses import dataclass, field

import numpy as np
from .polylines import add_bump


__all__ = ["TopologyView", "TopologyPath", "TopologyCrossing", "Topology"]


@dataclass(frozen=True, eq=False)
class TopologyView:
    """One view for :func:`resolve_topology`.

    Attributes
    ----------
    camera : Camera
    image : ndarray or callable
        RGB image (H, W, 3) uint8, or a callable returning it (loaded only when needed).
    mask : ndarray or callable
        Cable pixels (H, W) bool, or a callable returning them.
    junctions : ndarray or callable or None
        Pixels where the cable overlaps itself (optional).
    """

    camera: object
    image: object
    mask: object
    junctions: object = None


@dataclass(frozen=True, eq=False)
class TopologyPath:
    """One cable's centreline, in order.

    Attributes
    ----------
    points : ndarray, shape (N, 3)
        World positions along the cable (a closed path does not repeat its first point).
    closed : bool
        The cable is a loop.
    segments : tuple of tuple
        The segment graph's edges ``(start, end, key)`` followed, in order (a segment extended
        over a bridged gap keeps its far node and gets a new key).
    """

    points: np.ndarray
    closed: bool
    segments: tuple = ()


@dataclass(frozen=True, eq=False)
class TopologyCrossing:
    """Where one strand passes over another.

    Attributes
    ----------
    position : ndarray, shape (3,)
        Midway between the two strands at the crossing.
    over, under : tuple of int
        ``(path index, point index)`` of the upper and the lower strand at the crossing.
    confidence : float
        Probability that this crossing is right (strands paired and ordered as said), in [0, 1].
    junction : int or None
        The segment graph's junction node it was found at.
    cues : dict
        What decided it, for debugging: ``"height"`` and ``"image"``, the log-odds each cue
        gives this order over the flipped one (positive: for it); ``"pairing"``, the
        log-probability margin of the junction's matching over the next best;
        ``"pairing_probability"``, the matching's probability; ``"views"``, the number of
        views the image cue used.
    views : tuple of tuple
        ``(view index, weight, score)`` of the views the image cue used; a positive score
        supports this order.
    """

    position: np.ndarray
    over: tuple
    under: tuple
    confidence: float
    junction: object = None
    cues: dict = field(default_factory=dict)
    views: tuple = ()


@dataclass(frozen=True, eq=False)
class Topology:
    """Paths and crossings of the cable(s).

    Attributes
    ----------
    paths : tuple of TopologyPath
        One per cable.
    crossings : tuple of TopologyCrossing
        ``over``/``under`` index into ``paths`` and their points.
    warnings : tuple of str
        Ambiguous crossings, odd junctions, pieces that could not be joined.
    up : ndarray, shape (3,)
        What "over" means.
    bump_width : float
        Half width (world units, arc length) of the bump that lifts a strand at a crossing.
    """

    paths: tuple
    crossings: tuple
    warnings: tuple = ()
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    bump_width: float = 1.0

    def flipped(self, index):
        """The same topology with crossing ``index``'s over and under swapped.

        The two strands' heights at the crossing are swapped too (with the same smooth bump
        that lifted them), so the paths keep saying what the crossing list says. The
        crossing's confidence becomes that of the flipped order (its matching's probability
        less the old confidence); flipping twice gives the original back.

        Parameters
        ----------
        index : int

        Returns
        -------
        Topology
        """
        crossing = self.crossings[index]
        (op, oi), (upath, ui) = crossing.over, crossing.under
        points = [np.array(path.points, dtype=float) for path in self.paths]
        gap = float((points[op][oi] - points[upath][ui]) @ self.up)
        width = self.bump_width
        add_bump(points[op], self.paths[op].closed, oi, -gap, width, self.up)
        add_bump(points[upath], self.paths[upath].closed, ui, gap, width, self.up)
        paths = tuple(TopologyPath(p, path.closed, path.segments)
                      for p, path in zip(points, self.paths))
        crossings = list(self.crossings)
        pairing = crossing.cues.get("pairing_probability", 1.0)
        crossings[index] = TopologyCrossing(
            crossing.position, crossing.under, crossing.over,
            float(np.clip(pairing - crossing.confidence, 0.0, 1.0)), crossing.junction,
            {k: (-v if k in ("height", "image") else v) for k, v in crossing.cues.items()},
            tuple((v, w, -s) for v, w, s in crossing.views))
        return Topology(paths, tuple(crossings), self.warnings, self.up, self.bump_width)

    def to_result(self, radius, **fields):
        """A :class:`~engine.io.result.Result` with these paths and crossings.

        Parameters
        ----------
        radius : float
        **fields
            Other :class:`~engine.io.result.Result` fields (``cameras``, ``units``, ...).

        Returns
        -------
        Result
        """
        from ...io.result import CablePath, Crossing, Result, StrandRef

        paths = tuple(CablePath(path.points, closed=path.closed) for path in self.paths)
        crossings = tuple(Crossing(c.position, StrandRef(*c.over), StrandRef(*c.under),
                                   min(max(c.confidence, 0.0), 1.0)) for c in self.crossings)
        warnings = tuple(fields.pop("warnings", ())) + tuple(self.warnings)
        return Result(radius=radius, paths=paths, crossings=crossings, warnings=warnings,
                      **fields)
