"""A fast renderer of synthetic cable scenes, with no Blender: exact masks, plausible images.

The cable is ray-cast exactly (a dense sweep of spheres of the cable's radius along the
centreline: the tube's surface to within 1% of r, cut flat at free ends like Blender's filled
bevel caps), so its mask is the projected tube. The table is one textured plane, warped into
each view by its homography, so structure-from-motion sees the same surface from every view.
Clutter objects (boxes and cylinders standing on the table) are ray-cast exactly too and hide
what lies behind them, the cable included (its mask leaves those pixels out).

What the scene looks like comes from a :class:`~engine.synthetic.looks.Look`: the cable's colours
(plain, two-tone or striped) and gloss, the table's texture, the light (soft: blurred shadows;
hard: sharp shadows of the cable, lifted or not, and of the clutter, a tint and an uneven
brightness) and the camera's effects (exposure, vignetting, blur, noise, JPEG compression).
Shading: diffuse and ambient light, a specular streak along the cable, ambient occlusion where
a strand passes under another and on the table along the cable. A 30-view 960x720 scene renders
in seconds.

Only distortion-free cameras (PINHOLE, SIMPLE_PINHOLE) are supported.
"""

import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter, map_coordinates
from scipy.spatial import cKDTree

from ..geometry.polylines import arc_length
from .looks import DEFAULT_LOOK, Look
from .textures import legacy_wood_texture
from .textures import table_texture as look_texture

__all__ = ["table_texture", "table_square", "render_views", "render_masks", "place_clutter",
           "PlacedClutter", "jpeg_round_trip", "TABLE_EXTENT_FACTOR"]

log = logging.getLogger(__name__)

#: The table is a square this many times the cable's horizontal extent.
TABLE_EXTENT_FACTOR = 4.0
SPHERE_SPACING = 0.25  # r: spacing of the spheres that sweep the tube
_CABLE_ARC = 1000.0  # r: arc length the sweep puts between two cables
CLUTTER_CLEARANCE = 4.0  # r: least gap between a clutter object and the cable's footprint
BACKGROUND = (60, 60, 64)  # beyond the table's edge


def table_texture(look_or_seed=DEFAULT_LOOK, size=2048):
    """The table texture of a look, or the original bench's wood of a seed.

    Parameters
    ----------
    look_or_seed : Look or int
        A look (see :func:`engine.synthetic.textures.table_texture`), or a seed of
        :func:`engine.synthetic.textures.legacy_wood_texture` (the original bench's table).
    size : int, optional
        Pixels per side.

    Returns
    -------
    ndarray, shape (size, size, 3), uint8
    """
    if isinstance(look_or_seed, Look):
        return look_texture(look_or_seed, size)
    return legacy_wood_texture(int(look_or_seed), size)


@dataclass(frozen=True)
class PlacedClutter:
    """A clutter object standing on the table at its place in the scene (world units).

    Attributes
    ----------
    shape : str
        ``"box"`` or ``"cylinder"``.
    colour : tuple of int
        sRGB, 0-255.
    centre : tuple of float
        (x, y) of the footprint's centre on the table (z = 0).
    size : float
        Box side or cylinder diameter.
    height : float
    angle : float
        Rotation about the vertical, degrees.
    """

    shape: str
    colour: tuple
    centre: tuple
    size: float
    height: float
    angle: float

    @property
    def reach(self):
        """Radius of the circle around the centre that holds the footprint."""
        half = 0.5 * self.size
        return half * math.sqrt(2.0) if self.shape == "box" else half

    def footprint(self, samples=32):
        """Outline of the footprint on the table, (N, 2)."""
        half = 0.5 * self.size
        if self.shape == "box":
            local = np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
        else:
            angles = np.linspace(0.0, 2 * np.pi, samples, endpoint=False)
            local = half * np.column_stack([np.cos(angles), np.sin(angles)])
        c, s = math.cos(math.radians(self.angle)), math.sin(math.radians(self.angle))
        return local @ np.array([[c, s], [-s, c]]) + np.asarray(self.centre)

    def corners(self):
        """Corners of a box holding the object, (8, 3)."""
        outline = self.footprint() if self.shape == "box" else \
            PlacedClutter("box", self.colour, self.centre, self.size, self.height,
                          self.angle).footprint()
        return np.vstack([np.column_stack([outline, np.zeros(4)]),
                          np.column_stack([outline, np.full(4, self.height)])])


def place_clutter(truth, look):
    """Where a look's clutter objects stand: near the cable, never on its footprint.

    Each object stands at least :data:`CLUTTER_CLEARANCE` r from the cable's footprint on the
    table (and from the other objects), within the cable's bounding box widened a little so the
    views, which frame the cable, see it. The places are drawn from the look's seed.

    Parameters
    ----------
    truth : GroundTruth
    look : Look

    Returns
    -------
    tuple of PlacedClutter
        Objects that found no free place are left out (logged).
    """
    if not look.clutter:
        return ()
    r = truth.radius
    footprint = truth.centreline[:, :2]
    tree = cKDTree(footprint)
    low, high = footprint.min(axis=0), footprint.max(axis=0)
    extent = float(np.max(high - low)) + 2 * r
    rng = np.random.default_rng([look.seed, 91])
    clearance = (1.0 + CLUTTER_CLEARANCE) * r  # from the centreline
    placed = []
    for index, thing in enumerate(look.clutter):
        if thing.shape not in ("box", "cylinder"):
            raise ValueError(f"unknown clutter shape {thing.shape!r}")
        for attempt in range(600):  # widen the search now and then
            margin = extent * (0.05 + 0.1 * (attempt // 150))
            centre = rng.uniform(low - margin, high + margin)
            candidate = PlacedClutter(thing.shape, tuple(int(c) for c in thing.colour),
                                      (float(centre[0]), float(centre[1])), thing.size * r,
                                      thing.height * r, float(thing.angle))
            if _clutter_clear(candidate, tree, footprint, clearance) and all(
                    np.hypot(*np.subtract(other.centre, centre)) > other.reach
                    + candidate.reach + 2 * r for other in placed):
                placed.append(candidate)
                break
        else:
            log.info("clutter object %d found no free place on the table", index)
    return tuple(placed)


def _clutter_clear(thing, tree, footprint, clearance):
    """Whether every centreline point lies at least ``clearance`` outside the footprint."""
    centre = np.asarray(thing.centre)
    if thing.shape == "cylinder":
        return tree.query(centre)[0] >= 0.5 * thing.size + clearance
    near = tree.query_ball_point(centre, thing.reach + clearance)
    if not near:
        return True
    outline = thing.footprint().astype(np.float32)
    return all(cv2.pointPolygonTest(outline, (float(x), float(y)), True) <= -clearance
               for x, y in footprint[near])


def jpeg_round_trip(image, quality):
    """An RGB uint8 image as it reads back after JPEG compression at ``quality``.

    Returns
    -------
    image : ndarray, uint8
    data : bytes
        The JPEG file.
    """
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    decoded = cv2.imdecode(data, cv2.IMREAD_COLOR)
    return cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB), data.tobytes()


def render_masks(truth, cameras, look=None):
    """Exact cable masks only (no shading), e.g. for views rendered elsewhere.

    Parameters
    ----------
    truth : GroundTruth
    cameras : sequence of Camera
    look : Look, optional
        Its clutter (placed by :func:`place_clutter`) hides the cable behind it; nothing else
        of the look changes a mask.

    Yields
    ------
    ndarray, shape (H, W), bool
    """
    spheres, _, tangents, owner = _sweep(truth)
    caps = _end_caps(spheres, tangents, owner, truth.closed)
    clutter = place_clutter(truth, look) if look is not None else ()
    for camera in cameras:
        pixel, depth = _ray_cast(camera, spheres, truth.radius, caps)[:2]
        if clutter:
            keep = depth < _clutter_hits(camera, clutter)[1].reshape(-1)[pixel]
            pixel = pixel[keep]
        mask = np.zeros(camera.width * camera.height, dtype=bool)
        mask[pixel] = True
        yield mask.reshape(camera.height, camera.width)


def table_square(truth):
    """Centre (x, y) and side length of the square table under a cable, in world units."""
    return _table_geometry(truth)


def _table_geometry(truth):
    extent = np.ptp(truth.centreline[:, :2], axis=0).max() + 2 * truth.radius
    centre = 0.5 * (truth.centreline[:, :2].min(axis=0) + truth.centreline[:, :2].max(axis=0))
    return centre, TABLE_EXTENT_FACTOR * extent


def _texture_to_world(centre, side, size):
    """3x3 map from texture pixel (column, row) to table (x, y, 1); rows run towards -y."""
    step = side / size
    return np.array([[step, 0.0, centre[0] - 0.5 * side + 0.5 * step],
                     [0.0, -step, centre[1] + 0.5 * side - 0.5 * step],
                     [0.0, 0.0, 1.0]])


def _light_basis(light):
    """Two unit vectors square to the light and to each other."""
    side = np.cross(light, [0.0, 0.0, 1.0])
    if np.linalg.norm(side) < 1e-6:
        side = np.array([1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    return np.stack([side, np.cross(light, side)])


class _ShadowMap:
    """Depth of the cable towards a distant light: what lies in the cable's hard shadow.

    An orthographic height map of the sphere sweep seen from the light: a point is in shadow
    where the sweep's surface lies nearer the light than it does. Cells are ``cell`` wide
    across the light's azimuth and shorter along it by the sine of its elevation, so a low
    light's long shadows on the table keep smooth edges.
    """

    def __init__(self, spheres, radius, light, caps, cell=None):
        self.light = light
        self.basis = _light_basis(light)
        cell = radius / 6.0 if cell is None else cell
        self.cell = np.array([cell, cell * max(abs(light[2]), 0.1)])
        uv = spheres @ self.basis.T
        depth = spheres @ light
        self.origin = uv.min(axis=0) - 2 * radius
        shape = np.ceil((uv.max(axis=0) - self.origin + 2 * radius) / self.cell).astype(int) + 1
        self.depth = np.full(tuple(shape), -np.inf)
        reach = np.ceil(radius / self.cell).astype(int) + 1
        du, dv = np.meshgrid(np.arange(-reach[0], reach[0] + 1),
                             np.arange(-reach[1], reach[1] + 1))
        du, dv = du.ravel(), dv.ravel()
        for start in range(0, len(spheres), 512):
            index = np.arange(start, min(start + 512, len(spheres)))
            cell_u = np.round((uv[index, 0] - self.origin[0]) / self.cell[0]).astype(int)
            cell_v = np.round((uv[index, 1] - self.origin[1]) / self.cell[1]).astype(int)
            iu = cell_u[:, None] + du[None, :]
            iv = cell_v[:, None] + dv[None, :]
            pu = self.origin[0] + iu * self.cell[0] - uv[index, 0:1]
            pv = self.origin[1] + iv * self.cell[1] - uv[index, 1:2]
            d2 = pu * pu + pv * pv
            inside = d2 < radius * radius
            surface = depth[index, None] + np.sqrt(np.maximum(radius * radius - d2, 0.0))
            for _, end, outward, first, last in caps:  # nothing of the sweep beyond an end
                close = (index >= first) & (index <= last)
                if not close.any():
                    continue
                point = (spheres[index, None, :] + pu[..., None] * self.basis[0]
                         + pv[..., None] * self.basis[1]
                         + (surface - depth[index, None])[..., None] * light)
                beyond = (point - end) @ outward > 0
                inside &= ~(beyond & close[:, None])
            np.maximum.at(self.depth, (iu[inside], iv[inside]), surface[inside])

    def blocker_depth(self, points):
        """Depth towards the light of the sweep's surface over each point (-inf: none)."""
        uv = points @ self.basis.T
        iu = np.round((uv[:, 0] - self.origin[0]) / self.cell[0]).astype(np.int64)
        iv = np.round((uv[:, 1] - self.origin[1]) / self.cell[1]).astype(np.int64)
        inside = (iu >= 0) & (iu < self.depth.shape[0]) & (iv >= 0) & (iv < self.depth.shape[1])
        out = np.full(len(points), -np.inf)
        out[inside] = self.depth[iu[inside], iv[inside]]
        return out

    def shadowed(self, points, bias):
        """Whether each point lies in the cable's shadow (``bias`` guards against acne)."""
        return self.blocker_depth(points) > points @ self.light + bias


def _clutter_intersect(thing, origins, directions):
    """Nearest hit (parameter t > 0 along ``directions``) of rays on one clutter object.

    Returns
    -------
    t : ndarray
        ``inf`` where the ray misses.
    normal : ndarray, shape (N, 3)
        World normal at the hit.
    """
    angle = math.radians(thing.angle)
    c, s = math.cos(angle), math.sin(angle)
    rotation = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # world to local
    local_o = (origins - np.array([thing.centre[0], thing.centre[1], 0.0])) @ rotation.T
    local_d = directions @ rotation.T
    half, height = 0.5 * thing.size, thing.height
    count = len(origins)
    t = np.full(count, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        if thing.shape == "box":
            low = np.array([-half, -half, 0.0])
            high = np.array([half, half, height])
            t1 = (low - local_o) / local_d
            t2 = (high - local_o) / local_d
            near = np.where(np.isnan(t1), -np.inf, np.minimum(t1, t2))
            far = np.where(np.isnan(t1), np.inf, np.maximum(t1, t2))
            # A ray parallel to a slab misses unless it runs inside it.
            parallel = local_d == 0
            outside = parallel & ((local_o < low) | (local_o > high))
            near = np.where(parallel, -np.inf, near)
            far = np.where(parallel, np.inf, far)
            t_near = near.max(axis=1)
            t_far = far.min(axis=1)
            hit = (t_near <= t_far) & (t_near > 0) & ~outside.any(axis=1)
            t[hit] = t_near[hit]
            axis = near.argmax(axis=1)
            sign = -np.sign(local_d[np.arange(count), axis])
            local_n = np.zeros((count, 3))
            local_n[np.arange(count), axis] = sign
        else:
            a = local_d[:, 0] ** 2 + local_d[:, 1] ** 2
            b = local_o[:, 0] * local_d[:, 0] + local_o[:, 1] * local_d[:, 1]
            k = local_o[:, 0] ** 2 + local_o[:, 1] ** 2 - half * half
            disc = b * b - a * k
            side = (disc >= 0) & (a > 0)
            t_side = np.where(side, (-b - np.sqrt(np.maximum(disc, 0.0))) / a, np.inf)
            z_side = local_o[:, 2] + t_side * local_d[:, 2]
            side &= (t_side > 0) & (z_side >= 0) & (z_side <= height)
            t_top = (height - local_o[:, 2]) / local_d[:, 2]
            top_point = local_o + t_top[:, None] * local_d
            top = (local_d[:, 2] < 0) & (t_top > 0) \
                & (top_point[:, 0] ** 2 + top_point[:, 1] ** 2 <= half * half)
            t = np.where(side, t_side, np.inf)
            t = np.where(top & (t_top < t), t_top, t)
            use_top = top & (t == t_top)
            point = local_o + np.where(np.isfinite(t), t, 0.0)[:, None] * local_d
            local_n = np.column_stack([point[:, 0], point[:, 1], np.zeros(count)]) / half
            local_n[use_top] = (0.0, 0.0, 1.0)
    return t, local_n @ rotation


def _clutter_hits(camera, clutter):
    """Per pixel: which clutter object a view sees (-1: none), its depth and its normal."""
    width, height = camera.width, camera.height
    which = np.full((height, width), -1, dtype=np.int64)
    depth = np.full((height, width), np.inf)
    normal = np.zeros((height, width, 3))
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    for index, thing in enumerate(clutter):
        corners = camera.world_to_camera(thing.corners())
        if np.any(corners[:, 2] <= 0):
            box = (0, width, 0, height)
        else:
            u = fx * corners[:, 0] / corners[:, 2] + cx
            v = fy * corners[:, 1] / corners[:, 2] + cy
            box = (max(int(np.floor(u.min())) - 1, 0), min(int(np.ceil(u.max())) + 1, width),
                   max(int(np.floor(v.min())) - 1, 0), min(int(np.ceil(v.max())) + 1, height))
        if box[0] >= box[1] or box[2] >= box[3]:
            continue
        rows, cols = np.mgrid[box[2]:box[3], box[0]:box[1]]
        rays = np.stack([(cols.ravel() + 0.5 - cx) / fx, (rows.ravel() + 0.5 - cy) / fy,
                         np.ones(cols.size)], axis=1)
        t, n = _clutter_intersect(thing, np.broadcast_to(camera.center, rays.shape),
                                  rays @ camera.R)  # t is the camera depth
        window = depth[box[2]:box[3], box[0]:box[1]].reshape(-1)
        nearer = t < window
        flat_which = which[box[2]:box[3], box[0]:box[1]].reshape(-1)
        flat_normal = normal[box[2]:box[3], box[0]:box[1]].reshape(-1, 3)
        window[nearer] = t[nearer]
        flat_which[nearer] = index
        flat_normal[nearer] = n[nearer]
        depth[box[2]:box[3], box[0]:box[1]] = window.reshape(rows.shape)
        which[box[2]:box[3], box[0]:box[1]] = flat_which.reshape(rows.shape)
        normal[box[2]:box[3], box[0]:box[1]] = flat_normal.reshape(rows.shape + (3,))
    return which, depth, normal


def _clutter_shadowed(clutter, points, light, skip=None):
    """Whether a clutter object stands between each point and the (distant) light."""
    blocked = np.zeros(len(points), dtype=bool)
    directions = np.broadcast_to(light, points.shape)
    for index, thing in enumerate(clutter):
        if len(points) == 0:
            break
        candidates = np.ones(len(points), dtype=bool) if skip is None else skip != index
        if candidates.any():
            t = _clutter_intersect(thing, points[candidates], directions[candidates])[0]
            blocked[np.flatnonzero(candidates)[np.isfinite(t)]] = True
    return blocked


def _rotation_minimising_frame(tangents):
    """A unit vector square to the cable at each sphere that turns as little as it can."""
    frame = np.empty_like(tangents)
    reference = np.array([0.0, 0.0, 1.0])
    if abs(tangents[0] @ reference) > 0.9:
        reference = np.array([1.0, 0.0, 0.0])
    current = reference - (reference @ tangents[0]) * tangents[0]
    current /= np.linalg.norm(current)
    for k, tangent in enumerate(tangents):
        current = current - (current @ tangent) * tangent
        length = np.linalg.norm(current)
        if length < 1e-9:
            current = frame[k - 1] if k else reference
        else:
            current = current / length
        frame[k] = current
    return frame


def _uneven_field(look, size=33):
    """Smooth brightness multipliers over the table (texture-aligned grid, around 1)."""
    if look.uneven <= 0:
        return None
    rng = np.random.default_rng([look.seed, 57])
    field = np.zeros((size, size), dtype=np.float64)
    for cells, weight in ((2, 1.0), (4, 0.5), (7, 0.25)):
        grid = rng.random((cells + 1, cells + 1))
        field += weight * cv2.resize(grid, (size, size), interpolation=cv2.INTER_CUBIC)
    field = (field - field.min()) / (np.ptp(field) + 1e-12)
    return 1.0 + look.uneven * (2.0 * field - 1.0)


def _strand_occlusion(truth, spheres, sphere_arc):
    """Per sphere: how much another strand lying above shades it (1 = not at all)."""
    radius = truth.radius
    tree = cKDTree(spheres)
    occlusion = np.ones(len(spheres))
    pairs = tree.query_pairs(4.0 * radius, output_type="ndarray")
    if len(pairs) == 0:
        return occlusion
    length = sphere_arc[-1]
    gap = np.abs(sphere_arc[pairs[:, 0]] - sphere_arc[pairs[:, 1]])
    if truth.closed:
        gap = np.minimum(gap, length - gap)
    pairs = pairs[gap > 4.0 * radius]
    for oriented in (pairs, pairs[:, ::-1]):
        low, high = oriented[:, 0], oriented[:, 1]
        above = spheres[high, 2] > spheres[low, 2] + 0.5 * radius
        d = np.linalg.norm(spheres[high] - spheres[low], axis=1) / radius
        shade = np.where(above, 1.0 - 0.65 * np.exp(-((d - 2.0) / 0.9) ** 2), 1.0)
        np.minimum.at(occlusion, low, shade)
    return occlusion


def _sweep(truth):
    """Sphere centres along each cable, spaced ``SPHERE_SPACING`` r; arc length (each further
    cable ``_CABLE_ARC`` r on, so no arc window spans two); tangent; which cable."""
    spheres, arcs, tangents, owners = [], [], [], []
    offset = 0.0
    for number, (points, closed) in enumerate(truth.lines):
        if closed:
            points = np.vstack([points, points[:1]])
        arc = arc_length(points)
        samples = np.arange(0.0, arc[-1] + 1e-12, SPHERE_SPACING * truth.radius)
        if not closed and samples[-1] < arc[-1]:
            samples = np.append(samples, arc[-1])
        centres = np.column_stack([np.interp(samples, arc, points[:, k]) for k in range(3)])
        tangent = np.gradient(centres, axis=0)
        tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-30)
        spheres.append(centres)
        arcs.append(samples + offset)
        tangents.append(tangent)
        owners.append(np.full(len(samples), number))
        offset += arc[-1] + _CABLE_ARC * truth.radius
    return (np.vstack(spheres), np.concatenate(arcs), np.vstack(tangents),
            np.concatenate(owners))


def _end_caps(spheres, tangents, owner, closed):
    """Flat ends of open cables, as Blender's filled bevel caps: per end ``(sphere, centre,
    outward, first, last)``, ``first..last`` the spheres of its cable near enough to reach
    past it."""
    if closed:
        return ()
    near_end = int(np.ceil(1.0 / SPHERE_SPACING)) + 1
    caps = []
    for number in range(int(owner[-1]) + 1):
        members = np.flatnonzero(owner == number)
        start, stop = int(members[0]), int(members[-1])
        caps.append((start, spheres[start], -tangents[start], start,
                     min(start + near_end, stop)))
        caps.append((stop, spheres[stop], tangents[stop], max(stop - near_end, start), stop))
    return tuple(caps)


def _ray_cast(camera, spheres, radius, caps=()):
    """Nearest hit of each pixel's ray on the sphere sweep, cut flat at the cable's ends.

    Parameters
    ----------
    caps : sequence of (int, ndarray, ndarray, int, int)
        Per free end: its sphere index, centre, outward tangent and the spheres it cuts
        (:func:`_end_caps`). Those are cut by the plane through the end and the end disc is
        added.

    Returns
    -------
    pixels : ndarray of int
        Flat indices of the pixels that see the cable.
    depth : ndarray
        Depth (camera z) of each hit.
    sphere : ndarray of int
        Which sphere each hit lies on (for a cap: the end sphere).
    on_cap : ndarray of bool
        The hit lies on an end disc (its normal is the outward tangent).
    """
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    width, height = camera.width, camera.height
    centres = camera.world_to_camera(spheres)
    z = centres[:, 2]
    safe_z = np.maximum(z, 1e-12)
    u = fx * centres[:, 0] / safe_z + cx
    v = fy * centres[:, 1] / safe_z + cy
    # Bound of the sphere's silhouette in pixels (loose off-axis, exact test below).
    reach = np.where(z > 1.5 * radius,
                     max(fx, fy) * radius / np.sqrt(np.maximum(z * z - radius * radius, 1e-30))
                     * (1.0 + np.hypot(u - cx, v - cy) / max(fx, fy) * 0.5) + 1.5, 0.0)
    visible = (z > 1.5 * radius) & (u + reach >= 0) & (u - reach < width) \
        & (v + reach >= 0) & (v - reach < height)
    hits_pixel, hits_depth, hits_sphere, hits_cap = [], [], [], []
    index = np.flatnonzero(visible)
    half = np.ceil(reach[index]).astype(int)
    for h in np.unique(half):
        group = index[half == h]
        offsets = np.arange(-h, h + 1)
        dx, dy = np.meshgrid(offsets, offsets)
        px = (np.floor(u[group])[:, None] + dx.ravel()[None, :]).astype(np.int64)
        py = (np.floor(v[group])[:, None] + dy.ravel()[None, :]).astype(np.int64)
        inside = (px >= 0) & (px < width) & (py >= 0) & (py < height)
        which = np.broadcast_to(group[:, None], px.shape)[inside]
        px, py = px[inside], py[inside]
        ray = np.stack([(px + 0.5 - cx) / fx, (py + 0.5 - cy) / fy, np.ones(len(px))], axis=1)
        centre = centres[which]
        a = np.einsum("ij,ij->i", ray, ray)
        b = np.einsum("ij,ij->i", ray, centre)
        k = np.einsum("ij,ij->i", centre, centre) - radius * radius
        disc = b * b - a * k
        hit = disc >= 0
        t = (b[hit] - np.sqrt(disc[hit])) / a[hit]
        keep = np.ones(len(t), dtype=bool)
        for _, end, outward, first, last in caps:  # nothing of the sweep beyond a flat end
            end_camera = camera.R @ end + camera.t
            beyond = (ray[hit] * t[:, None] - end_camera) @ (camera.R @ outward) > 0
            keep &= ~(beyond & (which[hit] >= first) & (which[hit] <= last))
        hits_pixel.append((py[hit] * width + px[hit])[keep])
        hits_depth.append(t[keep])
        hits_sphere.append(which[hit][keep])
        hits_cap.append(np.zeros(int(keep.sum()), dtype=bool))
    for end_sphere, end, outward, _, _ in caps:  # the end discs themselves
        centre, normal = camera.R @ end + camera.t, camera.R @ outward
        if not visible[end_sphere]:
            continue
        h = int(np.ceil(reach[end_sphere]))
        rows, cols = np.mgrid[-h:h + 1, -h:h + 1]
        px = (np.floor(u[end_sphere]) + cols.ravel()).astype(np.int64)
        py = (np.floor(v[end_sphere]) + rows.ravel()).astype(np.int64)
        inside = (px >= 0) & (px < width) & (py >= 0) & (py < height)
        px, py = px[inside], py[inside]
        ray = np.stack([(px + 0.5 - cx) / fx, (py + 0.5 - cy) / fy, np.ones(len(px))], axis=1)
        facing = ray @ normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (centre @ normal) / facing
        on_disc = (facing != 0) & (t > 0) & (np.linalg.norm(ray * t[:, None] - centre, axis=1)
                                            <= radius)
        hits_pixel.append((py * width + px)[on_disc])
        hits_depth.append(t[on_disc])
        hits_sphere.append(np.full(int(on_disc.sum()), end_sphere))
        hits_cap.append(np.ones(int(on_disc.sum()), dtype=bool))
    if not hits_pixel:
        empty = np.zeros(0, dtype=np.int64)
        return empty, np.zeros(0), empty, np.zeros(0, dtype=bool)
    pixel = np.concatenate(hits_pixel)
    depth = np.concatenate(hits_depth)
    sphere = np.concatenate(hits_sphere)
    on_cap = np.concatenate(hits_cap)
    order = np.lexsort((depth, pixel))
    pixel, depth, sphere, on_cap = pixel[order], depth[order], sphere[order], on_cap[order]
    first = np.concatenate([[True], pixel[1:] != pixel[:-1]])
    return pixel[first], depth[first], sphere[first], on_cap[first]


def _texture_points(to_texture, points_xy):
    homogeneous = np.column_stack([points_xy, np.ones(len(points_xy))]) @ to_texture.T
    return homogeneous[:, :2]


def _clutter_shadow_outline(thing, light):
    """Outline of a clutter object's shadow on the table: its footprint and its projected top."""
    footprint = thing.footprint()
    top = footprint - thing.height * light[:2] / light[2]
    return np.vstack([footprint, top])


def _lit_table(truth, texture, look, centre, side, clutter, shadow_map, field):
    """The texture under the look's light, in table space: the cable's contact occlusion and
    shadows (of the cable and the clutter), the light's tint and its unevenness."""
    size = texture.shape[0]
    to_world = _texture_to_world(centre, side, size)
    to_texture = np.linalg.inv(to_world)
    pixel = side / size
    radius_px = truth.radius / pixel

    def texture_points(points_xy):
        return _texture_points(to_texture, points_xy)

    footprint = np.zeros((size, size), dtype=np.uint8)
    near = truth.centreline[truth.centreline[:, 2] < 3 * truth.radius]
    for point in texture_points(near[:, :2]):
        cv2.circle(footprint, (int(point[0]), int(point[1])), max(1, int(radius_px)), 255, -1)
    for thing in clutter:
        outline = np.round(texture_points(thing.footprint()) * 16).astype(np.int32)
        cv2.fillConvexPoly(footprint, outline, 255, cv2.LINE_8, 4)
    distance = cv2.distanceTransform(255 - footprint, cv2.DIST_L2, 5) * pixel / truth.radius
    occlusion = 1.0 - 0.45 * np.exp(-distance / 1.5)
    light = look.light_direction
    tint = np.asarray(look.light_tint, dtype=np.float64)
    direct = (1.0 - look.ambient) * max(light[2], 0.0)
    full = look.ambient + direct  # the table in full white light shows its texture as it is
    if look.light == "soft":
        shadow = np.zeros((size, size), dtype=np.uint8)
        for points, closed in truth.lines:  # each cable's soft shadow
            shifted = points[:, :2] - points[:, 2:3] * light[:2] / light[2]
            cv2.polylines(shadow, [np.round(texture_points(shifted)).astype(np.int32)],
                          bool(closed), 255, max(1, int(round(2 * radius_px))), cv2.LINE_AA)
        shadow = gaussian_filter(shadow.astype(np.float32) / 255.0,
                                 sigma=max(radius_px * 0.6, 1.0))
        for thing in clutter:  # blurred in a window around the object
            outline = texture_points(_clutter_shadow_outline(thing, light))
            sigma = max(radius_px * 0.6, 0.3 * thing.height / pixel, 1.0)
            low = np.maximum(np.floor(outline.min(axis=0) - 4 * sigma).astype(int), 0)
            high = np.minimum(np.ceil(outline.max(axis=0) + 4 * sigma).astype(int) + 1, size)
            if np.any(high <= low):
                continue
            cast = np.zeros((high[1] - low[1], high[0] - low[0]), dtype=np.float32)
            hull = cv2.convexHull(np.round((outline - low) * 16).astype(np.int32))
            cv2.fillConvexPoly(cast, hull, 1.0, cv2.LINE_AA, 4)
            window = shadow[low[1]:high[1], low[0]:high[0]]
            np.maximum(window, cv2.GaussianBlur(cast, (0, 0), sigma), out=window)
        factor = occlusion * (1.0 - 0.5 * shadow)
        table = texture * factor[..., None]
        if np.any(tint != 1.0):
            table = table * ((look.ambient + direct * tint) / full)[None, None, :]
    else:
        blocked = np.zeros((size, size), dtype=np.float32)
        columns = np.arange(size, dtype=np.float64)
        xs = to_world[0, 0] * columns + to_world[0, 2]
        for start in range(0, size, 256):  # the cable's sharp shadow, from the shadow map
            rows = np.arange(start, min(start + 256, size), dtype=np.float64)
            ys = to_world[1, 1] * rows + to_world[1, 2]
            grid = np.zeros((len(rows), size, 3))
            grid[..., 0] = xs[None, :]
            grid[..., 1] = ys[:, None]
            shaded = shadow_map.shadowed(grid.reshape(-1, 3), 0.05 * truth.radius)
            blocked[start:start + len(rows)] = shaded.reshape(len(rows), size)
        for thing in clutter:
            outline = texture_points(_clutter_shadow_outline(thing, light))
            hull = cv2.convexHull(np.round(outline * 16).astype(np.int32))
            cv2.fillConvexPoly(blocked, hull, 1.0, cv2.LINE_AA, 4)
        lit = 1.0 - cv2.GaussianBlur(blocked, (0, 0), max(0.8, 0.08 * radius_px))
        gain = (look.ambient + direct * lit[..., None] * tint[None, None, :]) / full
        table = texture * (occlusion[..., None] * gain)
    if field is not None:
        table = table * cv2.resize(field, (size, size), interpolation=cv2.INTER_LINEAR)[..., None]
    return np.clip(table, 0, 255).astype(np.uint8), to_world


def _sample_field(prepared, points):
    """The uneven light's multiplier at world points (1 if the light is even)."""
    field = prepared["field"]
    if field is None:
        return np.ones(len(points))
    texture = _texture_points(prepared["to_texture"], points[:, :2])
    scale = field.shape[0] / prepared["texture_size"]
    coords = [(texture[:, 1] + 0.5) * scale - 0.5, (texture[:, 0] + 0.5) * scale - 0.5]
    return map_coordinates(field, coords, order=1, mode="nearest")


def _prepare(truth, look, texture):
    """What every view shares: the lit table, the sweep, the clutter, the shadow map."""
    centre, side = _table_geometry(truth)
    clutter = place_clutter(truth, look)
    spheres, sphere_arc, tangents, owner = _sweep(truth)
    caps = _end_caps(spheres, tangents, owner, truth.closed)
    light = look.light_direction
    shadow_map = _ShadowMap(spheres, truth.radius, light, caps) if look.light == "hard" \
        else None
    field = _uneven_field(look)
    # Under a hard (low) light the cable and the clutter are lit on the table's scale: the
    # table in full light shows its texture as it is, so a surface facing up as the table
    # does shows its own colour. (Soft light keeps the original renderer's levels.)
    gain = 1.0 / (look.ambient + (1.0 - look.ambient) * max(light[2], 0.0)) \
        if look.light == "hard" else 1.0
    lit_table, to_world = _lit_table(truth, texture, look, centre, side, clutter, shadow_map,
                                     field)
    return dict(look=look, truth=truth, lit_table=lit_table, to_world=to_world,
                to_texture=np.linalg.inv(to_world), texture_size=texture.shape[0],
                field=field, gain=gain, clutter=clutter, spheres=spheres, sphere_arc=sphere_arc,
                tangents=tangents, owner=owner, caps=caps, shadow_map=shadow_map, light=light,
                occlusion=_strand_occlusion(truth, spheres, sphere_arc),
                frame=_rotation_minimising_frame(tangents)
                if look.stripe_colour is not None and look.stripe_period <= 0 else None)


def _direct_visibility(prepared, points, normals, skip=None):
    """1 where the hard light reaches a surface point, 0 in a cast shadow (soft light: 1)."""
    visible = np.ones(len(points))
    if prepared["shadow_map"] is None or len(points) == 0:
        return visible
    radius, light = prepared["truth"].radius, prepared["light"]
    cosine = np.clip(normals @ light, 0.05, 1.0)
    slope = np.sqrt(1.0 - cosine ** 2) / cosine
    bias = 0.08 * radius + 0.75 * prepared["shadow_map"].cell[0] * np.minimum(slope, 8.0)
    shaded = prepared["shadow_map"].shadowed(points, bias)
    if prepared["clutter"]:
        shaded |= _clutter_shadowed(prepared["clutter"], points + 1e-3 * radius * normals,
                                    light, skip)
    visible[shaded] = 0.0
    return visible


def _cable_colours(prepared, sphere, hit, normal, on_cap):
    """Per hit: the cable's colour there (two-tone halves or stripes; the other cables'
    colour), RGB 0..1."""
    look = prepared["look"]
    base = np.asarray(look.cable_colour, dtype=np.float64) / 255.0
    colours = np.broadcast_to(base, (len(sphere), 3))
    if look.other_cable_colour is not None:
        other = np.asarray(look.other_cable_colour, dtype=np.float64) / 255.0
        colours = np.where((prepared["owner"][sphere] > 0)[:, None], other[None, :], colours)
    if look.stripe_colour is None:
        return colours
    second = np.asarray(look.stripe_colour, dtype=np.float64) / 255.0
    tangents = prepared["tangents"][sphere]
    if look.stripe_period > 0:
        arc = prepared["sphere_arc"][sphere] + np.einsum(
            "ij,ij->i", hit - prepared["spheres"][sphere], tangents)
        band = np.floor(2.0 * arc / (look.stripe_period * prepared["truth"].radius)) % 2 == 1
    else:
        side = np.cross(tangents, prepared["frame"][sphere])
        band = np.einsum("ij,ij->i", normal, side) > 0
    band &= ~on_cap
    return np.where(band[:, None], second[None, :], colours)


def _render_view(prepared, camera):
    """One view before the camera's effects: float RGB image (0..1) and the exact mask."""
    look, truth = prepared["look"], prepared["truth"]
    light, tint = prepared["light"], np.asarray(look.light_tint, dtype=np.float64)
    spheres, tangents, caps = prepared["spheres"], prepared["tangents"], prepared["caps"]
    # Table: homography from texture pixels to image pixels (OpenCV pixel centres).
    plane = camera.K @ np.column_stack([camera.R[:, 0], camera.R[:, 1], camera.t])
    to_opencv = np.array([[1.0, 0.0, -0.5], [0.0, 1.0, -0.5], [0.0, 0.0, 1.0]])
    from_opencv = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]])
    homography = to_opencv @ plane @ prepared["to_world"] @ from_opencv
    image = cv2.warpPerspective(prepared["lit_table"], homography, (camera.width, camera.height),
                                flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                                borderValue=BACKGROUND).astype(np.float64) / 255.0
    flat = image.reshape(-1, 3)
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    # Cable: exact hits, hidden where a clutter object stands nearer.
    pixel, depth, sphere, on_cap = _ray_cast(camera, spheres, truth.radius, caps)
    if prepared["clutter"]:
        which, clutter_depth, clutter_normal = _clutter_hits(camera, prepared["clutter"])
        keep = depth < clutter_depth.reshape(-1)[pixel]
        pixel, depth, sphere, on_cap = pixel[keep], depth[keep], sphere[keep], on_cap[keep]
        seen = np.flatnonzero(which.reshape(-1) >= 0)
        if len(seen):
            rows, cols = np.divmod(seen, camera.width)
            ray = np.stack([(cols + 0.5 - cx) / fx, (rows + 0.5 - cy) / fy,
                            np.ones(len(cols))], 1)
            point = (ray * clutter_depth.reshape(-1)[seen][:, None] - camera.t) @ camera.R
            normal = clutter_normal.reshape(-1, 3)[seen]
            owner = which.reshape(-1)[seen]
            colour = np.array([thing.colour for thing in prepared["clutter"]],
                              dtype=np.float64)[owner] / 255.0
            visible = _direct_visibility(prepared, point, normal, skip=owner)
            direct = (1.0 - look.ambient) * np.clip(normal @ light, 0.0, None) * visible
            level = look.ambient + direct[:, None] * tint[None, :]
            flat[seen] = colour * level * (prepared["gain"]
                                           * _sample_field(prepared, point))[:, None]
    rows, cols = np.divmod(pixel, camera.width)
    ray = np.stack([(cols + 0.5 - cx) / fx, (rows + 0.5 - cy) / fy, np.ones(len(cols))], 1)
    hit_camera = ray * depth[:, None]
    hit = (hit_camera - camera.t) @ camera.R  # back to world
    normal = (hit - spheres[sphere]) / truth.radius
    # The tube's normal is square to the cable; the sweep's spheres tilt it by up to 7°
    # along the cable, which would show as ribs. The caps at free ends keep theirs.
    along = np.einsum("ij,ij->i", normal, tangents[sphere])
    normal -= along[:, None] * tangents[sphere]
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    for index, _, outward, _, _ in caps:  # flat ends face along the cable
        normal[on_cap & (sphere == index)] = outward
    view = camera.center - hit
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    diffuse = np.clip(normal @ light, 0.0, None)
    visible = np.ones(len(pixel))
    lit = diffuse > 0
    visible[lit] = _direct_visibility(prepared, hit[lit], normal[lit])
    halfway = view + light
    halfway /= np.linalg.norm(halfway, axis=1, keepdims=True)
    specular, shininess = look.gloss, max(4.0, 100.0 * look.gloss)
    highlight = specular * np.clip(np.einsum("ij,ij->i", normal, halfway), 0, 1) ** shininess
    shade = prepared["occlusion"][sphere] ** (0.5 + 0.5 * np.clip(normal[:, 2], 0, 1))
    contact = 0.75 + 0.25 * np.clip(normal[:, 2] + 1.0, 0.0, 1.0)  # darker underneath
    direct = (1 - look.ambient) * diffuse * visible
    light_level = (look.ambient + direct[:, None] * tint[None, :]) * shade[:, None] \
        * contact[:, None]
    colour = _cable_colours(prepared, sphere, hit, normal, on_cap)
    cable = colour * light_level + (highlight * visible)[:, None] * tint[None, :] \
        * shade[:, None]
    if prepared["field"] is not None:
        cable = cable * _sample_field(prepared, hit)[:, None]
    if prepared["gain"] != 1.0:
        cable = cable * prepared["gain"]
    flat[pixel] = cable
    mask = np.zeros(camera.width * camera.height, dtype=bool)
    mask[pixel] = True
    return image, mask.reshape(camera.height, camera.width)


def _sensor_gain(look, width, height):
    """Exposure times vignetting (darker towards the corners), per pixel; None if 1."""
    if look.vignetting <= 0 and look.exposure == 1.0:
        return None
    y, x = np.ogrid[0:height, 0:width]
    r2 = ((x + 0.5 - 0.5 * width) ** 2 + (y + 0.5 - 0.5 * height) ** 2) \
        / (0.25 * (width ** 2 + height ** 2))
    return (look.exposure * (1.0 - look.vignetting * r2))[..., None]


def _camera_effects(image, look, rng, gains):
    """Vignetting, exposure, blur and noise: the float image (0..1) as 8-bit RGB."""
    height, width = image.shape[:2]
    if (width, height) not in gains:
        gains[width, height] = _sensor_gain(look, width, height)
    if gains[width, height] is not None:
        image = image * gains[width, height]
    if look.blur > 0:
        image = cv2.GaussianBlur(image, (0, 0), look.blur)
    image = image * 255.0 + rng.normal(0.0, look.noise, image.shape)
    return np.clip(image, 0, 255).astype(np.uint8)


def render_views(truth, cameras, look=DEFAULT_LOOK, *, texture=None, texture_size=2048,
                 encoded=False):
    """Render every view of a synthetic scene in a look.

    Parameters
    ----------
    truth : GroundTruth
        The cable (the table is the plane z = 0 under it).
    cameras : sequence of Camera
        PINHOLE or SIMPLE_PINHOLE.
    look : Look, optional
        The cable's colours, the table, the light, the clutter and the camera's effects
        (the cable's lift is the layout's: see :func:`engine.synthetic.scene.make_scene`).
    texture : ndarray, optional
        Table texture (RGB uint8, square); :func:`table_texture` of ``look`` if None.
    texture_size : int, optional
        Pixels per side of the texture made when ``texture`` is None.
    encoded : bool, optional
        Also yield each view's JPEG file (None when ``look.jpeg_quality`` is 100).

    Yields
    ------
    image : ndarray, shape (H, W, 3), uint8
        RGB colour image, after a JPEG round trip at ``look.jpeg_quality`` when it is < 100.
    mask : ndarray, shape (H, W), bool
        Exact cable mask: pixels whose centre's ray meets the tube before any clutter.
    data : bytes or None
        Only with ``encoded``.
    """
    if not isinstance(look, Look):
        raise ValueError("look must be a Look (see engine.synthetic.looks)")
    for camera in cameras:
        if camera.model not in ("PINHOLE", "SIMPLE_PINHOLE"):
            raise ValueError(f"the fast renderer needs distortion-free cameras, "
                             f"{camera.name} is {camera.model}")
    if not 1 <= look.jpeg_quality <= 100:
        raise ValueError("jpeg_quality must be between 1 and 100")
    if texture is None:
        texture = table_texture(look, texture_size)
    prepared = _prepare(truth, look, texture)
    rng = np.random.default_rng([look.seed, 33])
    gains = {}
    for camera in cameras:
        image, mask = _render_view(prepared, camera)
        image = _camera_effects(image, look, rng, gains)
        data = None
        if look.jpeg_quality < 100:
            image, data = jpeg_round_trip(image, look.jpeg_quality)
        yield (image, mask, data) if encoded else (image, mask)
