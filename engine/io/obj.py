"""A result as a Wavefront OBJ tube mesh, for tools other than Blender."""

import numpy as np

from .files import write_atomic

__all__ = ["tube_mesh", "write_obj"]


def _frames(points, closed):
    """Unit tangents and a normal carried along the curve by parallel transport."""
    if closed:
        tangents = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    else:
        tangents = np.gradient(points, axis=0)
    tangents /= np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-300)
    helper = np.eye(3)[np.argmin(np.abs(tangents[0]))]
    normal = np.cross(tangents[0], helper)
    normals = [normal / np.linalg.norm(normal)]
    for tangent in tangents[1:]:
        normal = normals[-1] - (normals[-1] @ tangent) * tangent
        length = np.linalg.norm(normal)
        normals.append(normal / length if length > 1e-12 else normals[-1])
    normals = np.array(normals)
    return tangents, normals, np.cross(tangents, normals)


def tube_mesh(points, radius, *, closed=False, sides=12):
    """Vertices and quad faces (0-based) of a tube of ``radius`` around ``points``.

    Open tubes get a flat cap at each end (one polygon each).
    """
    points = np.asarray(points, dtype=float)
    _, normals, binormals = _frames(points, closed)
    angles = 2 * np.pi * np.arange(sides) / sides
    ring = np.cos(angles)[None, :, None] * normals[:, None] + \
        np.sin(angles)[None, :, None] * binormals[:, None]
    vertices = (points[:, None] + radius * ring).reshape(-1, 3)
    count = len(points)
    faces = []
    for i in range(count if closed else count - 1):
        j = (i + 1) % count
        for k in range(sides):
            m = (k + 1) % sides
            faces.append((i * sides + k, j * sides + k, j * sides + m, i * sides + m))
    if not closed:
        faces.append(tuple(range(sides))[::-1])
        faces.append(tuple((count - 1) * sides + k for k in range(sides)))
    return vertices, faces


def write_obj(result, path, *, overwrite=False, sides=12):
    """Write every path of ``result`` as a tube mesh object (units as the result's).

    Returns
    -------
    pathlib.Path
    """
    lines = [f"# cable_recon result: {len(result.paths)} path(s), radius {result.radius:.6g} "
             f"{result.units}"]
    offset = 1
    for number, cable in enumerate(result.paths):
        vertices, faces = tube_mesh(cable.points, result.radius, closed=cable.closed,
                                    sides=sides)
        lines.append(f"o cable_{number}")
        lines.extend(f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in vertices)
        lines.extend("f " + " ".join(str(offset + i) for i in face) for face in faces)
        offset += len(vertices)
    return write_atomic(path, "\n".join(lines) + "\n", overwrite=overwrite)
