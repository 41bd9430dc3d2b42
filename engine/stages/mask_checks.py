"""Checks that the masks held the cable, all of it and nothing else: a run warns when they
did not.

Masks that take in part of the table, a shadow or another object still carve, and the
reconstruction then ends in a curve that follows something other than the cable. Two
measures tell such runs apart from good ones without the truth:

* :func:`core_thickness`: the carved core's volume over that of a tube of the carved radius
  along the segment graph. A cable's core is a tube a little fatter than the cable (the hull
  is fat); masks that take in a patch of the table carve a slab.
* :func:`unexplained_share`: the share of the masks' pixels that lie away from the fitted
  curve's projection. A stray object or shadow that the other views carve too (so the
  agreement step keeps it) but that the curve does not follow stays in the masks.

Thresholds chosen on the tuning looks (8 families, seeds 0-2, 24 views at 960x720, true
cameras; our masks, the naive threshold's and the exact ones; 57 runs that finished): the 43
runs with one path and the exact masks' crossings had a thickness of 1.15-1.37 and at most
0.3% of the mask unexplained; 13 of the 14 wrong ones had a thickness of 14-1766 (a slab) or
2.4-97% unexplained. The one missed lost a stretch of the cable from its masks (nothing in
them to explain). On the held-out Cycles captures of ``samples/looks`` the exact masks give
1.29-1.57 (fewer, lower views carve a fatter hull) and 0.0%, and the three wrong runs are
flagged (4.8-54% unexplained). The thickness threshold was first 1.6, just over the tuning
runs; it was raised to 2.5 (still far under every slab) after those captures showed 1.57, so
they are no clean held-out test of it.

A core *thinner* than the tube is the other way masks go wrong: the hull of masks that agree
holds the cable, so a core under the tube its masks' width implies means some views miss
pixels that the others hold (a stretch lost, a shade side lost in some views only). On the
tuning looks (seeds 0-7, our masks and the exact ones) every run that ended right had a
thickness of at least 1.13 and the three thinnest wrong ones 0.83-0.97, so under 1.0 warns.
That check was added after held-out rows had been seen (a few wrong held-out runs at
0.91-0.94 with no warning); the threshold was set on the tuning seeds alone. Masks thinned in
some views only can still give a right curve (the fit follows each view's 2-D centre): the
warning says the masks disagree, not that the curve is wrong.
"""

from dataclasses import dataclass

import cv2
import numpy as np

from ..io.overlay import draw_projected
from ..io.packed_mask import unpacked
from ..settings import check_settings, setting

__all__ = ["CHECK_HINT", "MaskCheckSettings", "core_thickness", "unexplained_share",
           "mask_warnings"]

#: Every warning of these checks ends with this advice.
CHECK_HINT = "check them with `python -m engine segment`"


@dataclass(frozen=True)
class MaskCheckSettings:
    """When a run says its masks held more than the cable.

    Attributes
    ----------
    core_thickness : float
        Warn when the carved core holds more than this many times the volume of a tube of
        the carved radius along the segment graph (0 turns the check off).
    thin_core : float
        Warn when it holds less than this many times that volume: the masks disagree across
        views (0 turns the check off).
    unexplained : float
        Warn when, on average over the views, more than this share of the mask pixels lie
        outside the band around the fitted curve's projection (0 turns the check off).
    band : float
        The band's half-width in projected radii (plus one pixel): the hull is fat and the
        mask's outline a pixel off, so the band is wider than the cable.
    """

    core_thickness: float = setting(2.5, low=0)
    thin_core: float = setting(1.0, low=0)
    unexplained: float = setting(0.02, low=0, high=1)
    band: float = setting(1.5, low=0, unit="r")

    def __post_init__(self):
        check_settings(self)
        if 0 < self.core_thickness <= self.thin_core:
            raise ValueError("MaskCheckSettings.thin_core must be under core_thickness")


def core_thickness(core_voxels, voxel_size, radius, length):
    """The carved core's volume over that of a tube of ``radius`` and ``length``.

    Parameters
    ----------
    core_voxels : int
        Voxels in the core the segment graph was extracted from.
    voxel_size, radius, length : float
        In world units; ``length`` is the segment graph's total length.

    Returns
    -------
    float
        ``inf`` for a core with no length.
    """
    tube = np.pi * radius ** 2 * length
    if not tube > 0:
        return float("inf")
    return float(core_voxels * voxel_size ** 3 / tube)


def unexplained_share(paths, radius, views, *, band=1.5):
    """Per view, the share of the mask's pixels away from the curve's projection.

    Parameters
    ----------
    paths : sequence of (ndarray (N, 3), bool)
        The fitted centrelines and whether each is closed.
    radius : float
        The cable's radius, world units.
    views : sequence of View
        Registered frames with their (packed) masks.
    band : float, optional
        Half-width of the band around the projected centreline that explains a pixel, in
        projected radii (at the view's median depth), plus one pixel.

    Returns
    -------
    list of (str, float)
        ``(frame name, share)`` for each view with cable pixels.
    """
    shares = []
    for view in views:
        mask = unpacked(view.mask)
        count = int(np.count_nonzero(mask))
        if not count:
            continue
        camera = view.camera
        depths = np.concatenate([np.zeros(0)] + [camera.project(np.asarray(p, dtype=float))[1]
                                                 for p, _ in paths])
        depths = depths[depths > 0]
        if not len(depths):
            shares.append((camera.name, 1.0))
            continue
        pixel_radius = radius * float(np.mean(camera.focal)) / float(np.median(depths))
        thickness = max(3, int(round(2 * (band * pixel_radius + 1))))
        explained = np.zeros(mask.shape, np.uint8)
        for points, closed in paths:
            points = np.asarray(points, dtype=float)
            draw_projected(explained, camera, np.vstack([points, points[:1]]) if closed
                           else points, 1, thickness, line_type=cv2.LINE_8)
        away = np.count_nonzero(mask & (explained == 0))
        shares.append((camera.name, away / count))
    return shares


def mask_warnings(*, thickness=None, shares=(), settings=MaskCheckSettings()):
    """The warnings :func:`core_thickness` and :func:`unexplained_share` call for.

    Parameters
    ----------
    thickness : float, optional
    shares : sequence of (str, float), optional
    settings : MaskCheckSettings, optional

    Returns
    -------
    list of str
    """
    warnings = []
    check = ": " + CHECK_HINT
    if (thickness is not None and settings.core_thickness > 0
            and thickness > settings.core_thickness):
        warnings.append(f"the masks take in more than a cable: what they carve holds "
                        f"{thickness:.1f} times the volume of a tube along it (a shadow, part "
                        f"of the table or another object?)" + check)
    if thickness is not None and settings.thin_core > 0 and thickness < settings.thin_core:
        warnings.append(f"the masks disagree across views: what they carve holds only "
                        f"{thickness:.2f} times the volume of a tube as wide as they are "
                        f"(part of the cable missing from some of them?)" + check)
    if shares and settings.unexplained > 0:
        mean = float(np.mean([share for _, share in shares]))
        if mean > settings.unexplained:
            name, worst = max(shares, key=lambda item: item[1])
            warnings.append(f"{100 * mean:.0f}% of the mask pixels lie away from the curve "
                            f"({100 * worst:.0f}% in {name}): the masks hold something "
                            f"besides the cable, or part of the cable was not reconstructed"
                            + check)
    return warnings
