"""Table textures of synthetic looks: wood, voronoi cells, woven fabric, printed paper, tiles and a
plain surface, coloured and seeded by a :class:`~engine.synthetic.looks.Look`.

Every kind but ``plain`` carries corners and blobs at several scales, none of them periodic over
the table, so structure-from-motion (SIFT) matches the table between views. The same look gives
the same texture; the default look (family ``"default"``) gives the original bench's light oak
(:func:`legacy_wood_texture`), so the original bench keeps its numbers.
"""

import cv2
import numpy as np

from .looks import LOOK_FAMILIES, TABLE_KINDS

__all__ = ["table_texture", "legacy_wood_texture"]


def table_texture(look, size=2048):
    """The table surface of a look.

    Parameters
    ----------
    look : Look
        Its ``table`` kind, ``table_colour``, ``table_accent``, ``table_contrast`` and ``seed``
        are used; a look of family ``"default"`` gives :func:`legacy_wood_texture` of its seed.
    size : int, optional
        Pixels per side.

    Returns
    -------
    ndarray, shape (size, size, 3), uint8
        RGB, as seen under even white light (the renderer lights it).
    """
    if size < 64:
        raise ValueError("the texture must be at least 64 pixels wide")
    if look.table not in TABLE_KINDS:
        raise ValueError(f"unknown table kind {look.table!r}")
    if look.family == "default":
        return legacy_wood_texture(look.seed, size)
    family = LOOK_FAMILIES.index(look.family)  # another family's table of the same seed differs
    rng = np.random.default_rng([look.seed, family, TABLE_KINDS.index(look.table), 4127])
    base = np.asarray(look.table_colour, dtype=np.float32)
    accent = _distinct_accent(base, np.asarray(look.table_accent, dtype=np.float32))
    contrast = float(np.clip(look.table_contrast, 0.0, 1.0))
    maker = {"wood": _wood, "voronoi": _voronoi, "weave": _weave, "paper": _paper,
             "tiles": _tiles, "plain": _plain}[look.table]
    image = maker(rng, size, base, accent, contrast)
    return np.clip(image, 0, 255).astype(np.uint8)


def legacy_wood_texture(seed, size=2048):
    """The original bench's table (RGB uint8): light oak grain and muted blotches.

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


# --- helpers ------------------------------------------------------------------------------------

def _value_noise(rng, size, octaves=range(2, 9), falloff=0.6, shape=None):
    """Smooth noise in 0..1 summed over octaves (cells of 2**octave per side)."""
    height, width = shape if shape is not None else (size, size)
    image = np.zeros((height, width), dtype=np.float32)
    for octave in octaves:
        cells = 2 ** octave
        grid = rng.random((cells + 1, cells + 1)).astype(np.float32)
        image += cv2.resize(grid, (width, height), interpolation=cv2.INTER_CUBIC) \
            * falloff ** octave
    return (image - image.min()) / (np.ptp(image) + 1e-9)


MIN_ACCENT_GAP = 50.0  # 8-bit luma levels between the table's colour and its texture's accent


def _luma(colour):
    return float(np.dot(colour, [0.299, 0.587, 0.114]))


def _distinct_accent(base, accent):
    """The accent, moved away from the base in brightness if the two are too alike to give
    structure-from-motion features (a look's accent may be as close as a few levels)."""
    gap = _luma(accent) - _luma(base)
    if abs(gap) >= MIN_ACCENT_GAP:
        return accent
    direction = np.sign(gap) if gap != 0 else (-1.0 if _luma(base) > 128 else 1.0)
    moved = accent + direction * (MIN_ACCENT_GAP - abs(gap))
    if np.any(moved < 0) or np.any(moved > 255):  # no room that way: go the other way
        moved = base - direction * MIN_ACCENT_GAP
    return np.clip(moved, 0, 255).astype(np.float32)


def _mix(base, accent, weight):
    """``base`` where ``weight`` is 0, ``accent`` where it is 1 (float RGB image)."""
    return base[None, None, :] + (accent - base)[None, None, :] * weight[..., None]


def _strength(contrast):
    """How strongly the texture's marks show: never so faint that SIFT finds nothing."""
    return 0.5 + 0.5 * contrast


def _marks(rng, canvas, count, base, accent, strength, *, max_axis, min_axis=2, angle=None,
           stretch=1.0):
    """Filled ellipses of colours between ``base`` and ``accent`` (blobs for SIFT).

    ``angle``: degrees, spread about 0 (None: any); ``stretch`` lengthens the first axis.
    """
    size = canvas.shape[0]
    for _ in range(count):
        t = float(rng.uniform(0.3, 1.0)) * strength
        colour = base + (accent - base) * t * float(rng.choice([-0.6, 1.0, 1.3]))
        colour = colour + rng.normal(0, 6, 3)
        centre = tuple(int(v) for v in rng.integers(0, size, 2))
        axes = rng.integers(min_axis, max(min_axis + 1, max_axis), 2)
        axes = (int(axes[0] * stretch), int(axes[1]))
        tilt = float(rng.uniform(0, 180)) if angle is None else float(rng.normal(0, angle))
        cv2.ellipse(canvas, centre, axes, tilt, 0, 360, np.clip(colour, 0, 255).tolist(), -1,
                    cv2.LINE_AA)


# --- kinds --------------------------------------------------------------------------------------

def _wood(rng, size, base, accent, contrast):
    """Grain: warped stripes along x with knots, blotches and scratches."""
    strength = _strength(contrast)
    rows = np.arange(size, dtype=np.float32)[:, None]
    warp = _value_noise(rng, size, octaves=range(1, 5), falloff=0.7) * size * 0.08
    fine = _value_noise(rng, size, octaves=range(5, 9), falloff=0.8)
    rings = np.float32(size / float(rng.uniform(12.0, 25.0)))
    phase = (rows + warp) / rings * 2 * np.pi
    grain = 0.5 + 0.5 * np.sin(phase + 3.0 * fine)
    grain = grain ** 3  # thin dark late-wood lines
    streaks = cv2.resize(rng.random((size, 48)).astype(np.float32), (size, size),
                         interpolation=cv2.INTER_LINEAR)  # long fibres along x
    streaks = cv2.resize(rng.random((size // 2, 24)).astype(np.float32), (size, size),
                         interpolation=cv2.INTER_CUBIC) * 0.5 + streaks * 0.5
    weight = np.clip(0.65 * grain + 0.35 * streaks, 0, 1) * strength
    canvas = _mix(base, accent, weight)
    _marks(rng, canvas, 600, base, accent, 0.6 * strength, max_axis=size // 90, angle=8.0,
           stretch=2.5)  # pores and streaks along the grain
    for _ in range(int(rng.integers(6, 14))):  # knots
        centre = tuple(int(v) for v in rng.integers(0, size, 2))
        axes = (int(rng.integers(size // 120, size // 40)), int(rng.integers(size // 200,
                                                                              size // 80)))
        for ring in range(4, 0, -1):
            colour = base + (accent - base) * strength * (0.4 + 0.2 * ring)
            cv2.ellipse(canvas, centre, (axes[0] * ring // 2 + 1, axes[1] * ring // 2 + 1), 0,
                        0, 360, colour.tolist(), -1 if ring == 1 else 2, cv2.LINE_AA)
    for _ in range(200):  # scratches
        start = rng.integers(0, size, 2)
        end = start + rng.integers(-size // 12, size // 12, 2)
        cv2.line(canvas, tuple(int(v) for v in start), tuple(int(v) for v in end),
                 (base + (accent - base) * strength * 1.2).tolist(), int(rng.integers(1, 4)),
                 cv2.LINE_AA)
    return canvas * (0.9 + 0.2 * _value_noise(rng, size, octaves=range(2, 6)))[..., None]


def _voronoi(rng, size, base, accent, contrast):
    """Irregular cells (stone, cork, terrazzo): a shade per cell and dark cell borders."""
    strength = _strength(contrast)
    count = int(rng.integers(900, 1800))
    points = rng.integers(0, size, (count, 2))
    seeds = np.full((size, size), 255, dtype=np.uint8)
    seeds[points[:, 1], points[:, 0]] = 0
    distance, labels = cv2.distanceTransformWithLabels(seeds, cv2.DIST_L2, 5,
                                                       labelType=cv2.DIST_LABEL_PIXEL)
    shade = rng.random(labels.max() + 1).astype(np.float32)
    weight = shade[labels] * strength
    border = np.zeros((size, size), dtype=bool)
    border[:, 1:] |= labels[:, 1:] != labels[:, :-1]
    border[1:, :] |= labels[1:, :] != labels[:-1, :]
    border = cv2.dilate(border.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(np.float32)
    border = cv2.GaussianBlur(border, (0, 0), 1.0)
    canvas = _mix(base, accent, weight)
    dark = np.minimum(base, accent) * 0.6
    canvas = canvas * (1 - border[..., None] * strength) + dark * border[..., None] * strength
    speckle = _value_noise(rng, size, octaves=range(6, 10), falloff=0.9)
    canvas *= (0.92 + 0.16 * speckle)[..., None]
    _marks(rng, canvas, 250, base, accent, strength, max_axis=size // 150)
    return canvas


def _weave(rng, size, base, accent, contrast):
    """Woven fabric: over/under warp and weft threads, uneven dye, a few slubs and stains."""
    strength = _strength(contrast)
    period = int(rng.integers(max(6, size // 220), max(8, size // 110)))
    index = np.arange(size)
    # Threads wander a little so the weave is not exactly periodic.
    wobble_x = (_value_noise(rng, size, octaves=range(2, 5), shape=(1, size))[0] - 0.5) * period
    wobble_y = (_value_noise(rng, size, octaves=range(2, 5), shape=(1, size))[0] - 0.5) * period
    x = index[None, :] + wobble_y[:, None]
    y = index[:, None] + wobble_x[None, :]
    column, row = np.floor(x / period).astype(np.int64), np.floor(y / period).astype(np.int64)
    across_x = (x / period) % 1.0  # across a vertical (warp) thread
    across_y = (y / period) % 1.0
    warp_on_top = ((column + row) % 2) == 0
    profile_x = np.sin(np.pi * across_x) ** 0.6
    profile_y = np.sin(np.pi * across_y) ** 0.6
    thread_shade = 0.75 + 0.25 * np.where(warp_on_top, profile_x, profile_y)
    warp_dye = rng.random(size // period + 3).astype(np.float32)
    weft_dye = rng.random(size // period + 3).astype(np.float32)
    dye = np.where(warp_on_top, warp_dye[np.clip(column, 0, len(warp_dye) - 1)],
                   weft_dye[np.clip(row, 0, len(weft_dye) - 1)])
    weight = np.where(warp_on_top, 0.15, 0.85) * 0.7 + 0.3 * dye
    mottle = _value_noise(rng, size, octaves=range(2, 7), falloff=0.7)
    weight = np.clip(weight * strength + (mottle - 0.5) * 0.6 * strength, 0, 1.2)
    canvas = _mix(base, accent, weight.astype(np.float32))
    canvas *= thread_shade[..., None].astype(np.float32)
    # Slubs, lint and stains: blobs that make each patch of fabric unique.
    _marks(rng, canvas, 500, base, accent, strength, max_axis=max(4, period))
    stains = np.zeros((size, size), dtype=np.float32)
    for _ in range(int(rng.integers(40, 80))):
        centre = tuple(int(v) for v in rng.integers(0, size, 2))
        axes = tuple(int(v) for v in rng.integers(size // 80, size // 25, 2))
        cv2.ellipse(stains, centre, axes, float(rng.uniform(0, 180)), 0, 360,
                    float(rng.uniform(0.3, 1.0)), -1, cv2.LINE_AA)
    stains = cv2.GaussianBlur(stains, (0, 0), 3.0)
    canvas *= (1.0 - 0.3 * strength * np.clip(stains, 0, 1))[..., None]
    return canvas


_GLYPHS = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789%&#@?"


def _paper(rng, size, base, accent, contrast):
    """Printed sheets: lines of text, ruled lines, boxes and figures on a fibrous paper."""
    strength = _strength(contrast)
    fibre = _value_noise(rng, size, octaves=range(4, 10), falloff=0.85)
    canvas = base[None, None, :] * (0.94 + 0.08 * fibre[..., None])
    # Ink stands out from the paper towards the accent (darker on a light table, lighter on
    # a dark one), however close the accent is.
    away = accent - base
    if np.abs(away).max() < 40:
        away = away * 40 / max(np.abs(away).max(), 1.0) if np.abs(away).max() > 0 else \
            np.full(3, -40.0 if base.mean() > 100 else 40.0, dtype=np.float32)
    ink = np.clip(base + away * (0.9 + 1.1 * strength), 0, 255)
    scale = size / 2048.0
    # Overlapping sheets, slightly darker or lighter than the table, each with its own print,
    # most of them around the middle, which is what the views of the cable see.
    for _ in range(int(rng.integers(8, 13))):
        width, height = (int(v * scale) for v in rng.integers(450, 800, 2))
        middle = rng.uniform(0.15, 0.85, 2) * size
        left, top = int(middle[0] - width / 2), int(middle[1] - height / 2)
        sheet = np.clip(base * float(rng.uniform(0.93, 1.07)), 0, 255)
        cv2.rectangle(canvas, (left, top), (left + width, top + height), sheet.tolist(), -1)
        cv2.rectangle(canvas, (left, top), (left + width, top + height),
                      (sheet * 0.85).tolist(), max(1, int(2 * scale)))
        _print_sheet(rng, canvas, (left, top, width, height), ink, scale)
    return canvas


def _print_sheet(rng, canvas, box, ink, scale):
    """Paragraphs of random glyphs, rules, a table grid and a figure inside ``box``."""
    left, top, width, height = box
    margin = int(30 * scale) + 1
    y = top + margin
    font_scale = float(rng.uniform(0.5, 0.9)) * scale
    line_height = int(32 * font_scale) + 2
    colour = ink.tolist()
    thickness = max(1, int(round(2 * font_scale)))
    while y < top + height - margin:
        block = rng.random()
        if block < 0.6:  # a paragraph of words
            for _ in range(int(rng.integers(2, 7))):
                x = left + margin + int(rng.integers(0, 3)) * int(20 * scale)
                while x < left + width - margin - 40 * scale:
                    word = "".join(rng.choice(list(_GLYPHS), int(rng.integers(2, 9))))
                    cv2.putText(canvas, word, (x, y), cv2.FONT_HERSHEY_SIMPLEX, font_scale,
                                colour, thickness, cv2.LINE_AA)
                    x += int((len(word) + 1) * 19 * font_scale)
                y += line_height
                if y >= top + height - margin:
                    break
        elif block < 0.75:  # a heading
            word = "".join(rng.choice(list(_GLYPHS[:26]), int(rng.integers(3, 8))))
            cv2.putText(canvas, word, (left + margin, y + line_height), cv2.FONT_HERSHEY_DUPLEX,
                        font_scale * 1.8, colour, thickness + 1, cv2.LINE_AA)
            y += 2 * line_height
        elif block < 0.88:  # a table grid with numbers
            cells = int(rng.integers(2, 6)), int(rng.integers(2, 5))
            cell_w = (width - 2 * margin) // cells[0]
            for r in range(cells[1] + 1):
                cv2.line(canvas, (left + margin, y + r * line_height),
                         (left + margin + cells[0] * cell_w, y + r * line_height), colour, 1)
            for c in range(cells[0] + 1):
                cv2.line(canvas, (left + margin + c * cell_w, y),
                         (left + margin + c * cell_w, y + cells[1] * line_height), colour, 1)
            for r in range(cells[1]):
                for c in range(cells[0]):
                    number = str(int(rng.integers(0, 10 ** int(rng.integers(1, 5)))))
                    cv2.putText(canvas, number, (left + margin + c * cell_w + 4,
                                                 y + (r + 1) * line_height - 6),
                                cv2.FONT_HERSHEY_PLAIN, font_scale * 1.4, colour, 1, cv2.LINE_AA)
            y += (cells[1] + 1) * line_height
        else:  # a figure: a filled blob, a circle, a polyline chart
            size = int(rng.integers(60, 160) * scale) + 4
            x = left + margin + int(rng.integers(0, max(1, width - 2 * margin - size)))
            cv2.circle(canvas, (x + size // 2, y + size // 2), size // 2, colour, thickness,
                       cv2.LINE_AA)
            cv2.rectangle(canvas, (x + size // 4, y + size // 4),
                          (x + size // 2, y + 3 * size // 4), colour, -1)
            chart = np.column_stack([np.linspace(x + size + 10, x + 3 * size, 8),
                                     y + size * rng.random(8)]).astype(np.int32)
            cv2.polylines(canvas, [chart], False, colour, thickness, cv2.LINE_AA)
            y += size + line_height


def _tiles(rng, size, base, accent, contrast):
    """Square tiles of varying shade, with grout lines, chips and speckle."""
    strength = _strength(contrast)
    count = int(rng.integers(10, 22))
    tile = size / count
    grout = max(2, int(tile * float(rng.uniform(0.04, 0.09))))
    index = np.arange(size)
    # Rows of tiles may be offset (running bond) and every tile has its own shade.
    offset = float(rng.choice([0.0, 0.5]))
    row = (index // tile).astype(np.int64)
    column_pos = index[None, :] + (row[:, None] % 2) * offset * tile
    column = np.floor(column_pos / tile).astype(np.int64)
    shade = rng.random((count + 2, count + 2)).astype(np.float32)
    weight = shade[row[:, None], column] * 0.6 * strength
    within_x = column_pos - column * tile
    within_y = (index - row * tile)[:, None]
    in_grout = (within_x < grout) | (within_y < grout)
    canvas = _mix(base, accent, weight)
    speckle = _value_noise(rng, size, octaves=range(5, 10), falloff=0.9)
    canvas *= (0.9 + 0.2 * speckle)[..., None]
    _marks(rng, canvas, 1400, base, accent, strength, max_axis=max(3, int(tile / 10)))
    grout_colour = np.clip(accent * 0.7 if accent.mean() < base.mean() else accent * 1.1, 0, 255)
    grout_colour = base + (grout_colour - base) * min(1.0, strength * 1.3)
    canvas[in_grout] = grout_colour + rng.normal(0, 4, (int(in_grout.sum()), 3))
    return canvas


def _plain(rng, size, base, accent, contrast):
    """A nearly uniform surface with faint noise (too little for structure-from-motion)."""
    noise = _value_noise(rng, size, octaves=range(2, 9), falloff=0.7)
    amount = 0.04 + 0.1 * contrast
    weight = noise * amount
    return _mix(base, accent, weight.astype(np.float32))
