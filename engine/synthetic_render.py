"""A fast renderer of synthetic cable scenes, with no Blender: exact masks, plausible images.

The cable is ray-cast exactly (a dense sweep of spheres of the cable's radius along the
centreline: the tube's surface to within 1% of r, cut flat at free ends like Blender's filled
bevel caps), so its mask is the projected tube. The
table is one textured plane, warped into each view by its homography, so structure-from-motion
sees the same surface from every view. Shading: diffuse and ambient light, a specular streak
along the cable, ambient occlusion where a strand passes under another and on the table along
the cable, and the cable's soft shadow on the table. A 30-view 960x720 scene renders in seconds.

Only distortion-free cameras (PINHOLE, SIMPLE_PINHOLE) are supported.
"""

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.spatial import cKDTree

__all__ = ["RenderSettings", "table_texture", "table_square", "render_views", "render_masks",
           "TABLE_EXTENT_FACTOR"]

#: The table is a square this many times the cable's horizontal extent.
TABLE_EXTENT_FACTOR = 4.0
SPHERE_SPACING = 0.25  # r: spacing of the spheres that sweep the tube


@dataclass(frozen=True)
class RenderSettings:
    """Look of a fast-rendered scene.

    Attributes
    ----------
    cable_colour : tuple of int
        RGB of the cable.
    light_azimuth, light_elevation : float
        Degrees; direction towards the (distant) light.
    ambient : float
        Share of light that does not depend on the surface orientation.
    specular : float
        Strength of the highlight along the cable.
    shininess : float
        Blinn-Phong exponent: larger is a thinner streak.
    texture_size : int
        Pixels per side of the table texture.
    noise : float
        Standard deviation of the sensor noise, in 8-bit levels.
    blur : float
        Gaussian blur of the optics, pixels.
    seed : int
        Seeds the table texture and the noise.
    """

    cable_colour: tuple = (205, 45, 35)
    light_azimuth: float = 35.0
    light_elevation: float = 55.0
    ambient: float = 0.35
    specular: float = 0.6
    shininess: float = 60.0
    texture_size: int = 2048
    noise: float = 2.0
    blur: float = 0.6
    seed: int = 0

    @property
    def light(self):
        """Unit vector towards the light."""
        azimuth, elevation = math.radians(self.light_azimuth), math.radians(self.light_elevation)
        return np.array([math.cos(azimuth) * math.cos(elevation),
                         math.sin(azimuth) * math.cos(elevation), math.sin(elevation)])


def table_texture(seed, size=2048):
    """A desaturated, feature-rich table surface (RGB uint8): wood-like grain and blotches.

    Low saturation keeps any coloured cable distinct; many corners and blobs at every scale
    give structure-from-motion features to match.
    """
    rng = np.random.default_rng([seed, 21])
    image = np.zeros((size, size), dtype=np.float32)
    for octave in range(2, 9):  # value noise over several scales
        cells = 2 ** octave
        grid = rng.random((cells + 1, cells + 1)).astype(np.float32)
        image += cv2.resize(grid, (size, size), interpolation=cv2.INTER_CUBIC) * 0.6 ** octave
    image = (image - image.min()) / (np.ptp(image) + 1e-9)
    base = np.array([150, 128, 104], dtype=np.float32)  # light oak
    rgb = base[None, None, :] * (0.7 + 0.6 * image[..., None])
    canvas = rgb.copy()
    for _ in range(900):  # flecks and blotches of muted colours
        colour = base * rng.uniform(0.45, 1.35) + rng.normal(0, 10, 3)
        centre = tuple(int(v) for v in rng.integers(0, size, 2))
        axes = tuple(int(v) for v in rng.integers(2, max(3, size // 60), 2))
        cv2.ellipse(canvas, centre, axes, float(rng.uniform(0, 180)), 0, 360,
                    colour.tolist(), -1, cv2.LINE_AA)
    for _ in range(250):  # scratches and edges
        start = rng.integers(0, size, 2)
        end = start + rng.integers(-size // 12, size // 12, 2)
        shade = float(rng.uniform(0.5, 0.8))
        cv2.line(canvas, tuple(int(v) for v in start), tuple(int(v) for v in end),
                 (base * shade).tolist(), int(rng.integers(1, 4)), cv2.LINE_AA)
    mixed = 0.55 * canvas + 0.45 * rgb
    return np.clip(mixed, 0, 255).astype(np.uint8)


def render_masks(truth, cameras):
    """Exact cable masks only (no shading), e.g. for views rendered elsewhere.

    Yields
    ------
    ndarray, shape (H, W), bool
    """
    spheres, _, tangents = _sweep(truth)
    caps = _end_caps(spheres, tangents, truth.closed)
    for camera in cameras:
        pixel = _ray_cast(camera, spheres, truth.radius, caps)[0]
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


def _lit_table(truth, texture, settings, centre, side):
    """The texture darkened by the cable's contact occlusion and soft shadow, in table space."""
    size = texture.shape[0]
    to_world = _texture_to_world(centre, side, size)
    to_texture = np.linalg.inv(to_world)
    pixel = side / size
    radius_px = truth.radius / pixel

    def texture_points(points_xy):
        homogeneous = np.column_stack([points_xy, np.ones(len(points_xy))]) @ to_texture.T
        return homogeneous[:, :2]

    footprint = np.zeros((size, size), dtype=np.uint8)
    near = truth.centreline[truth.centreline[:, 2] < 3 * truth.radius]
    for point in texture_points(near[:, :2]):
        cv2.circle(footprint, (int(point[0]), int(point[1])), max(1, int(radius_px)), 255, -1)
    distance = cv2.distanceTransform(255 - footprint, cv2.DIST_L2, 5) * pixel / truth.radius
    occlusion = 1.0 - 0.45 * np.exp(-distance / 1.5)
    light = settings.light
    shifted = truth.centreline[:, :2] - truth.centreline[:, 2:3] * light[:2] / light[2]
    shadow = np.zeros((size, size), dtype=np.uint8)
    points = np.round(texture_points(shifted)).astype(np.int32)
    cv2.polylines(shadow, [points], bool(truth.closed), 255,
                  max(1, int(round(2 * radius_px))), cv2.LINE_AA)
    shadow = gaussian_filter(shadow.astype(np.float32) / 255.0, sigma=max(radius_px * 0.6, 1.0))
    factor = occlusion * (1.0 - 0.5 * shadow)
    return np.clip(texture * factor[..., None], 0, 255).astype(np.uint8), to_world


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
    """Sphere centres along the centreline, spaced ``SPHERE_SPACING`` r; arc length; tangent."""
    points = truth.centreline
    if truth.closed:
        points = np.vstack([points, points[:1]])
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(steps)])
    samples = np.arange(0.0, arc[-1] + 1e-12, SPHERE_SPACING * truth.radius)
    if not truth.closed and samples[-1] < arc[-1]:
        samples = np.append(samples, arc[-1])
    spheres = np.column_stack([np.interp(samples, arc, points[:, k]) for k in range(3)])
    tangents = np.gradient(spheres, axis=0)
    tangents /= np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-30)
    return spheres, samples, tangents


def _end_caps(spheres, tangents, closed):
    """Flat ends of an open cable, as Blender's filled bevel caps: (sphere, centre, outward)."""
    if closed:
        return ()
    return ((0, spheres[0], -tangents[0]), (len(spheres) - 1, spheres[-1], tangents[-1]))


def _ray_cast(camera, spheres, radius, caps=()):
    """Nearest hit of each pixel's ray on the sphere sweep, cut flat at the cable's ends.

    Parameters
    ----------
    caps : sequence of (int, ndarray, ndarray)
        Per free end: its sphere index, centre and outward tangent (:func:`_end_caps`). The
        sweep is cut by the plane through the end and the end disc is added.

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
        near_end = int(np.ceil(1.0 / SPHERE_SPACING)) + 1  # spheres reaching past the end
        for end_sphere, end, outward in caps:  # nothing of the sweep lies beyond a flat end
            end_camera = camera.R @ end + camera.t
            beyond = (ray[hit] * t[:, None] - end_camera) @ (camera.R @ outward) > 0
            keep &= ~(beyond & (np.abs(which[hit] - end_sphere) <= near_end))
        hits_pixel.append((py[hit] * width + px[hit])[keep])
        hits_depth.append(t[keep])
        hits_sphere.append(which[hit][keep])
        hits_cap.append(np.zeros(int(keep.sum()), dtype=bool))
    for end_sphere, end, outward in caps:  # the end discs themselves
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


def render_views(truth, cameras, settings=RenderSettings(), *, texture=None):
    """Render every view of a synthetic scene.

    Parameters
    ----------
    truth : GroundTruth
        The cable (the table is the plane z = 0 under it).
    cameras : sequence of Camera
        PINHOLE or SIMPLE_PINHOLE.
    settings : RenderSettings, optional
    texture : ndarray, optional
        Table texture (RGB uint8, square); :func:`table_texture` of ``settings.seed`` if None.

    Yields
    ------
    image : ndarray, shape (H, W, 3), uint8
        RGB colour image.
    mask : ndarray, shape (H, W), bool
        Exact cable mask: pixels whose centre's ray meets the tube.
    """
    for camera in cameras:
        if camera.model not in ("PINHOLE", "SIMPLE_PINHOLE"):
            raise ValueError(f"the fast renderer needs distortion-free cameras, "
                             f"{camera.name} is {camera.model}")
    if texture is None:
        texture = table_texture(settings.seed, settings.texture_size)
    centre, side = _table_geometry(truth)
    lit_table, to_world = _lit_table(truth, texture, settings, centre, side)
    spheres, sphere_arc, tangents = _sweep(truth)
    caps = _end_caps(spheres, tangents, truth.closed)
    occlusion = _strand_occlusion(truth, spheres, sphere_arc)
    colour = np.asarray(settings.cable_colour, dtype=np.float64) / 255.0
    light = settings.light
    rng = np.random.default_rng([settings.seed, 33])
    for camera in cameras:
        # Table: homography from texture pixels to image pixels (OpenCV pixel centres).
        plane = camera.K @ np.column_stack([camera.R[:, 0], camera.R[:, 1], camera.t])
        to_opencv = np.array([[1.0, 0.0, -0.5], [0.0, 1.0, -0.5], [0.0, 0.0, 1.0]])
        from_opencv = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]])
        homography = to_opencv @ plane @ to_world @ from_opencv
        image = cv2.warpPerspective(lit_table, homography, (camera.width, camera.height),
                                    flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                                    borderValue=(60, 60, 64)).astype(np.float64) / 255.0
        # Cable: exact hits, shaded.
        pixel, depth, sphere, on_cap = _ray_cast(camera, spheres, truth.radius, caps)
        rows, cols = np.divmod(pixel, camera.width)
        (fx, fy), (cx, cy) = camera.focal, camera.principal_point
        ray = np.stack([(cols + 0.5 - cx) / fx, (rows + 0.5 - cy) / fy, np.ones(len(cols))], 1)
        hit_camera = ray * depth[:, None]
        hit = (hit_camera - camera.t) @ camera.R  # back to world
        normal = (hit - spheres[sphere]) / truth.radius
        # The tube's normal is square to the cable; the sweep's spheres tilt it by up to 7°
        # along the cable, which would show as ribs. The caps at free ends keep theirs.
        along = np.einsum("ij,ij->i", normal, tangents[sphere])
        normal -= along[:, None] * tangents[sphere]
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        for index, _, outward in caps:  # flat ends face along the cable
            normal[on_cap & (sphere == index)] = outward
        view = camera.center - hit
        view /= np.linalg.norm(view, axis=1, keepdims=True)
        diffuse = np.clip(normal @ light, 0.0, None)
        halfway = view + light
        halfway /= np.linalg.norm(halfway, axis=1, keepdims=True)
        highlight = settings.specular * np.clip(np.einsum("ij,ij->i", normal, halfway), 0, 1) \
            ** settings.shininess
        shade = occlusion[sphere] ** (0.5 + 0.5 * np.clip(normal[:, 2], 0, 1))
        contact = 0.75 + 0.25 * np.clip(normal[:, 2] + 1.0, 0.0, 1.0)  # darker underneath
        light_level = (settings.ambient + (1 - settings.ambient) * diffuse) * shade * contact
        cable = colour[None, :] * light_level[:, None] + highlight[:, None] * shade[:, None]
        flat = image.reshape(-1, 3)
        flat[pixel] = cable
        mask = np.zeros(camera.width * camera.height, dtype=bool)
        mask[pixel] = True
        if settings.blur > 0:
            image = cv2.GaussianBlur(image, (0, 0), settings.blur)
        image = image * 255.0 + rng.normal(0.0, settings.noise, image.shape)
        yield np.clip(image, 0, 255).astype(np.uint8), mask.reshape(camera.height, camera.width)
