"""The image cue: which strand is on top where each view separates them, from paths traced
between the branches' anchors in the image."""

import itertools
import math

import cv2
import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from ...progress import check_cancel
from ...threads import map_in_threads
from .context import load

__all__ = ["image_cue"]


def image_cue(junctions, views, context, report, cancel, workers=1):
    """Fill each junction's ``view_costs``: shortest-path costs between its branch points,
    the views read on ``workers`` threads (see :func:`~engine.threads.thread_count`) and their
    costs added in the views' order."""
    r = context.r
    usable = [j for j in junctions if len(j.branches) >= 3 and not j.greedy]
    if not usable or not views:
        return
    # Points of the whole cable (about one per radius), to find views where it hides a junction.
    cable = []
    for _, _, data in context.graph.graph.edges(data=True):
        points = np.asarray(data["points"], dtype=float)
        step = max(int(round(r / max(context.spacing, 1e-12))), 1)
        cable.append(points[::step])
    cable = np.vstack(cable) if cable else np.zeros((0, 3))
    local = [np.linalg.norm(cable - j.centre, axis=1) <= j.anchor_distance + 3.0 * r
             for j in usable]

    def read(index):
        check_cancel(cancel, "resolving the topology")
        return _view_costs(index, views[index], usable, local, cable, context)

    def done(index):
        report((index + 1) / len(views), "reading the images at the junctions")

    report(0.0, "reading the images at the junctions")
    found = map_in_threads(workers, "image-cue", read, range(len(views)), done)
    for costs in found:
        for number, entry in costs:
            usable[number].view_costs.append(entry)


def _view_costs(index, view, usable, local, cable, context):
    """``(junction number, (index, weight, costs))`` of each usable junction the view
    ``index`` shows clearly (its image and mask loaded only if one does)."""
    r, s = context.r, context.settings
    camera = view.camera
    mask = image = junction_mask = None
    cable_px, cable_depth = camera.project(cable)
    found = []
    for number, (junction, near) in enumerate(zip(usable, local)):
        points = np.vstack([junction.centre] + [b.anchor for b in junction.branches])
        pixels, depth = camera.project(points)
        if not np.all(depth > 0) or not np.all(np.isfinite(pixels)):
            continue
        r_px = camera.focal[0] * r / depth[0]
        if r_px < s.min_pixel_radius:
            continue
        pad = 2.0 * r_px + 3.0
        if (pixels[:, 0].min() < pad or pixels[:, 1].min() < pad
                or pixels[:, 0].max() > camera.width - pad
                or pixels[:, 1].max() > camera.height - pad):
            continue
        weight = _view_weight(camera, junction, pixels, r_px, context)
        if weight <= 0:
            continue
        if _occluded(pixels, depth[0], cable_px[~near], cable_depth[~near], r_px, r, camera, s):
            continue
        if mask is None:
            mask = load(view.mask, bool)
            image = load(view.image)
            junction_mask = load(view.junctions, bool) if view.junctions is not None else None
            if image is None or mask is None:
                raise ValueError(f"views[{index}]: no image or no mask")
            if mask.shape != image.shape[:2]:
                raise ValueError(f"views[{index}]: the image is {image.shape[1::-1]}, its "
                                 f"mask {mask.shape[::-1]}")
        if junction_mask is not None and not _near_junction_pixel(junction_mask, pixels[0],
                                                                  2.0 * r_px):
            weight *= 0.5
        costs = _path_costs(image, mask, pixels[1:], r_px, s)
        if costs is not None:
            found.append((number, (index, weight, costs)))
    return found


def _view_weight(camera, junction, pixels, r_px, context):
    """How much a view can say about a junction: top-down, strands apart, cable large enough."""
    s = context.settings
    towards = camera.center - junction.centre
    cosine = float(towards @ context.up / max(np.linalg.norm(towards), 1e-12))
    if cosine <= 0:
        return 0.0
    top = cosine ** s.top_down_power
    # The largest sine of the angle between two projected chords through the junction.
    chords = pixels[1:] - pixels[0]
    norms = np.linalg.norm(chords, axis=1)
    if np.any(norms < 1e-9):
        return 0.0
    units = chords / norms[:, None]
    sines = np.abs(units[:, None, 0] * units[None, :, 1] - units[:, None, 1] * units[None, :, 0])
    angle = float(np.sort(sines.ravel())[-1]) if sines.size else 0.0
    size = float(np.clip((r_px - s.min_pixel_radius) / 2.0, 0.0, 1.0))
    return top * angle * size


def _occluded(pixels, depth, other_px, other_depth, r_px, r_world, camera, settings):
    """Another part of the cable, in front, projects onto the strands' paths."""
    if len(other_px) == 0:
        return False
    ahead = np.isfinite(other_px[:, 0]) & (other_depth > 0) & (other_depth < depth - r_world)
    if not ahead.any():
        return False
    candidates = other_px[ahead]
    reach = (settings.occluder_margin + 1.0) * r_px
    centre = pixels[0]
    for end in pixels[1:]:
        d = end - centre
        t = np.clip((candidates - centre) @ d / max(d @ d, 1e-12), 0.0, 1.0)
        if np.any(np.linalg.norm(candidates - centre - t[:, None] * d, axis=1) < reach):
            return True
    return False


def _near_junction_pixel(junction_mask, pixel, reach):
    x, y = pixel
    rows = slice(max(int(y - reach), 0), int(y + reach) + 1)
    cols = slice(max(int(x - reach), 0), int(x + reach) + 1)
    return bool(junction_mask[rows, cols].any())


def _path_costs(image, mask, anchors, r_px, settings):
    """Shortest-path costs on the image gradient between every two projected branch points.

    Returns a dict ``{(i, j): cost}`` over branch index pairs (i < j), infinite for a branch
    point that finds no cable pixel near it; None when fewer than two find one.
    """
    height, width = mask.shape
    pad = int(math.ceil(2.0 * r_px + 3))
    x0 = max(int(math.floor(anchors[:, 0].min())) - pad, 0)
    x1 = min(int(math.ceil(anchors[:, 0].max())) + pad + 1, width)
    y0 = max(int(math.floor(anchors[:, 1].min())) - pad, 0)
    y1 = min(int(math.ceil(anchors[:, 1].max())) + pad + 1, height)
    if x1 - x0 < 3 or y1 - y0 < 3:
        return None
    patch = np.asarray(image[y0:y1, x0:x1], dtype=np.float32)
    cable = np.asarray(mask[y0:y1, x0:x1], dtype=bool)
    anchors = np.asarray(anchors, dtype=float) - [x0, y0]  # COLMAP coordinates in the patch
    if r_px > settings.path_radius:  # reduced: the cable's radius path_radius pixels
        scale = settings.path_radius / r_px
        size = (max(int(round((x1 - x0) * scale)), 3), max(int(round((y1 - y0) * scale)), 3))
        patch = cv2.resize(patch, size, interpolation=cv2.INTER_AREA)
        cable = cv2.resize(cable.view(np.uint8) * np.float32(1.0), size,
                           interpolation=cv2.INTER_AREA) >= 0.5
        anchors = anchors * [size[0] / (x1 - x0), size[1] / (y1 - y0)]
        r_px = settings.path_radius
    if patch.ndim == 2:
        patch = patch[..., None]
    if not cable.any():
        return None
    smooth = cv2.GaussianBlur(patch, (0, 0), 0.7)
    if smooth.ndim == 2:
        smooth = smooth[..., None]
    # Specular highlights are the brightest cable pixels: clipped, they make no edges.
    clip = np.percentile(smooth[cable], 100.0 * settings.highlight_clip, axis=0)
    clipped = np.ascontiguousarray(np.minimum(smooth, clip[None, None, :]), dtype=np.float32)
    gx = cv2.Sobel(clipped, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(clipped, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    if gx.ndim == 2:
        gx, gy = gx[..., None], gy[..., None]
    gradient = np.sqrt(gx ** 2 + gy ** 2).max(axis=2)
    inside = cv2.dilate(cable.view(np.uint8), np.ones((3, 3), np.uint8)) > 0
    cost = settings.edge_floor + 1e-3 + gradient ** 2 / settings.edge_scale
    cost[~inside] += 255.0
    value = smooth.max(axis=2)
    sources = {}
    search = max(settings.highlight_search * r_px, 1.5)
    rows, cols = np.indices(cable.shape)
    for k, (x, y) in enumerate(anchors):
        col, row = x - 0.5, y - 0.5
        for reach in (search, 2.0 * search):
            near = ((rows - row) ** 2 + (cols - col) ** 2 <= reach ** 2) & cable
            if near.any():
                flat = np.flatnonzero(near)
                sources[k] = int(flat[np.argmax(value.ravel()[flat])])
                break
    if len(sources) < 2:
        return None
    found = sorted(sources)
    distances = _dijkstra(cost, [sources[k] for k in found])
    costs = {}
    for i, j in itertools.combinations(range(len(anchors)), 2):
        costs[(i, j)] = (float(distances[found.index(i), sources[j]])
                         if i in sources and j in sources else math.inf)
    return costs


def _dijkstra(cost, sources):
    """Path costs (mean of the two pixels' costs times the step length) from ``sources``."""
    h, w = cost.shape
    index = np.arange(h * w).reshape(h, w)
    rows, cols, weights = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        first, last = max(-dc, 0), w - max(dc, 0)
        a = index[0:h - dr, first:last]
        b = index[dr:h, first + dc:last + dc]
        step = math.hypot(dr, dc)
        rows.append(a.ravel())
        cols.append(b.ravel())
        weights.append(0.5 * (cost.ravel()[a.ravel()] + cost.ravel()[b.ravel()]) * step)
    graph = sparse.csr_matrix((np.concatenate(weights), (np.concatenate(rows),
                                                        np.concatenate(cols))), shape=(h * w,) * 2)
    return csgraph.dijkstra(graph, directed=False, indices=sources)
