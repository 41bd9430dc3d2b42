"""Discrete elastic rods (Bergou et al. 2008) at static equilibrium (paper §3.4).

A rod is a chain of vertices ``x_0 .. x_{N-1}`` (closed rods join the last to the first) with a
radius per vertex. Its elastic energy is the sum of

* stretching, per edge ``j``: ``1/2 E A_j (|e_j| / l_j - 1)**2 l_j``, with ``A = pi r**2`` and
  ``l_j`` the rest length: a stiff spring that keeps the rod nearly inextensible;
* bending, per interior vertex ``i``: ``E I_i |kb_i|**2 / (l_{i-1} + l_i)``, with
  ``I = pi r**4 / 4`` and the discrete curvature binormal
  ``kb_i = 2 e_{i-1} x e_i / (|e_{i-1}| |e_i| + e_{i-1} . e_i)`` (``|kb| = 2 tan(phi / 2)`` for a
  turning angle ``phi``); the rest shape is straight;
* twisting, for an isotropic rod treated quasi-statically (see below).

Twist. For an isotropic rod the material frame enters the energy only through the twist, so it
can be minimised out analytically instead of being stored:

* with a free (or pinned) end, or a closed rod, the frame turns freely and the twist energy is
  zero at equilibrium; a closed rod's link is unknown from images, so it is taken as relaxed;
* with both ends of an open rod clamped, the total twist ``Theta`` between the clamps is fixed
  (the clamps' relative turn ``end_twist`` plus the holonomy of the space-parallel-transported
  frame along the centreline) and the optimal twist is spread uniformly, ``m_i ~ D_i / (G J_i)``,
  giving ``1/2 Theta**2 / sum_i (D_i / (G J_i))``, with ``J = pi r**4 / 2`` and ``D_i`` the
  Voronoi length of vertex ``i``. Its gradient is the holonomy gradient of Bergou et al.; its
  Hessian is a rank-one term (applied with the Woodbury identity) plus ``Theta`` times the
  holonomy's Hessian, which is banded. The holonomy is measured from the reference shape's,
  so the centreline may deform until it has changed by half a turn.

Ends: ``"free"``; ``"pinned"`` (the end vertex held at its reference position); ``"clamped"``
(the end edge's two vertices held: position and tangent fixed, and the material frame too).

Equilibrium is found by energy minimisation, never by time stepping: Newton's method with the
analytic gradient and Hessian and a backtracking (Armijo) line search. Each iteration first
tries the exact Hessian (quadratic convergence near equilibrium); if it is indefinite or its
step needs much shortening, the Hessian with every element's block projected onto positive
semi-definite matrices is used instead, so every step descends. The sparse Hessian of an open
rod is banded and factored by banded Cholesky; long-range terms (closed rods, contacts) go
through sparse LU; rank-one terms (twist) through the Woodbury identity.

Energy terms beyond the rod's own (loads, data terms of a fit) plug into the same solver: a
term has a ``name`` and a ``model(points)`` method returning an object with ``energy(points)``
and ``derivatives(points, *, exact=False)`` (a :class:`Derivatives`). The model is rebuilt once
per Newton iteration (a data term may refresh its nearest-point matches there) and fixed during
the line search. A solve stops when the full Newton step moves no vertex more than the step
tolerance, or when refreshed models stop lowering the energy (matches cycling between states).
"""

import logging
import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded
from scipy.sparse import csc_matrix
from scipy.sparse.linalg import splu

from ..geometry.arrays import as_points, read_only
from ..progress import check_cancel

__all__ = ["END_CONDITIONS", "RodSettings", "Rod", "Derivatives", "ElasticEnergy", "Load",
           "EndMoment", "Equilibrium", "solve_rod", "minimise_energy", "block_hessian",
           "project_psd"]

log = logging.getLogger(__name__)

#: How a rod's end may be held.
END_CONDITIONS = ("free", "pinned", "clamped")

_ARMIJO = 1e-4  # sufficient decrease of the line search
_BAND = 12  # widest band (in degrees of freedom) factored as a banded matrix
_RESOLUTION = 1e-12  # relative energy change below which a failed line search is converged
_STALL = 3  # iterations without a lower energy (after refreshing the models) before giving up
_SETTLED = 10.0  # ... converged if the last step was within this many step tolerances


@dataclass(frozen=True)
class RodSettings:
    """Material and solver settings of a rod (SI units unless said otherwise).

    Attributes
    ----------
    youngs_modulus : float
        Young's modulus ``E`` in Pa (soft PVC cable sheath: about 10 MPa).
    poisson_ratio : float
        Gives the shear modulus ``G = E / (2 (1 + nu))`` of the twist stiffness.
    density : float
        kg/m^3, for gravity.
    gravity : tuple of float or None
        Gravitational acceleration (m/s^2) as a vector, e.g. ``(0, 0, -9.81)``; None for none.
    max_iterations : int
        Newton iterations before giving up (the result then says it did not converge).
    step_tolerance : float
        Converged when the full Newton step moves no vertex more than this, in units of the
        rod's mean radius.
    max_step : float
        No vertex moves more than this (in mean radii) in one iteration; ``inf`` for no limit.
    """

    youngs_modulus: float = 10e6
    poisson_ratio: float = 0.5
    density: float = 1300.0
    gravity: tuple = None
    max_iterations: int = 200
    step_tolerance: float = 1e-6
    max_step: float = math.inf

    def __post_init__(self):
        if not self.youngs_modulus > 0 or not math.isfinite(self.youngs_modulus):
            raise ValueError("youngs_modulus must be a positive number")
        if not -1.0 < self.poisson_ratio <= 0.5:
            raise ValueError("poisson_ratio must lie in (-1, 0.5]")
        if not self.density >= 0:
            raise ValueError("density must not be negative")
        if self.gravity is not None:
            gravity = tuple(float(g) for g in self.gravity)
            if len(gravity) != 3 or not all(math.isfinite(g) for g in gravity):
                raise ValueError("gravity must be three finite numbers or None")
            object.__setattr__(self, "gravity", gravity)
        if int(self.max_iterations) < 1:
            raise ValueError("max_iterations must be at least 1")
        if not self.step_tolerance > 0:
            raise ValueError("step_tolerance must be positive")
        if not self.max_step > 0:
            raise ValueError("max_step must be positive (inf for no limit)")

    @property
    def shear_modulus(self):
        """``G = E / (2 (1 + nu))`` in Pa."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))


@dataclass(frozen=True, eq=False)
class Rod:
    """A rod's reference configuration, cross-section and ends.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Reference positions: they give the rest lengths (unless ``rest_lengths`` is given), the
        positions of held end vertices and the clamps' frames.
    radius : float or array_like, shape (N,)
        Radius per vertex (a single value for a uniform rod).
    closed : bool, optional
        The last vertex joins the first (ends must then be free).
    start, end : str, optional
        One of :data:`END_CONDITIONS` for vertex 0 and vertex N-1.
    end_twist : float, optional
        With both ends clamped: how far (radians) the end clamp is turned about the rod's axis
        relative to the start clamp, beyond the twist-free reference. Ignored otherwise.
    rest_lengths : array_like, optional
        Rest length per edge (N-1 edges, or N for a closed rod).
    """

    points: np.ndarray
    radius: np.ndarray
    closed: bool = False
    start: str = "free"
    end: str = "free"
    end_twist: float = 0.0
    rest_lengths: np.ndarray = None

    def __post_init__(self):
        points = as_points(self.points)
        count = len(points)
        if count < (3 if self.closed else 2):
            raise ValueError("a rod needs at least 2 vertices (3 when closed)")
        radius = np.broadcast_to(np.asarray(self.radius, dtype=np.float64), (count,)).copy()
        if not (np.all(np.isfinite(radius)) and np.all(radius > 0)):
            raise ValueError("radius must be positive and finite")
        for name in ("start", "end"):
            if getattr(self, name) not in END_CONDITIONS:
                raise ValueError(f"{name} must be one of {', '.join(END_CONDITIONS)}")
        if self.closed and (self.start != "free" or self.end != "free"):
            raise ValueError("a closed rod has no ends to hold")
        if "clamped" in (self.start, self.end) and count < 3:
            raise ValueError("a clamped rod needs at least 3 vertices")
        edges = self.edge_vertices(count, self.closed)
        if self.rest_lengths is None:
            rest = np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1)
        else:
            rest = np.array(self.rest_lengths, dtype=np.float64).reshape(-1)
            if rest.shape != (len(edges),):
                raise ValueError(f"rest_lengths must hold {len(edges)} values, one per edge")
        if not (np.all(np.isfinite(rest)) and np.all(rest > 0)):
            raise ValueError("rest lengths must be positive: no two consecutive points may "
                             "coincide")
        object.__setattr__(self, "points", read_only(points))
        object.__setattr__(self, "radius", read_only(radius))
        object.__setattr__(self, "rest_lengths", read_only(rest))
        object.__setattr__(self, "closed", bool(self.closed))
        object.__setattr__(self, "end_twist", float(self.end_twist))

    @staticmethod
    def edge_vertices(count, closed):
        """Vertex pairs ``(E, 2)`` of the edges of a chain of ``count`` vertices."""
        first = np.arange(count if closed else count - 1)
        return np.column_stack([first, (first + 1) % count])

    @property
    def edges(self):
        """Vertex pairs ``(E, 2)`` of the edges."""
        return self.edge_vertices(len(self.points), self.closed)

    @property
    def bends(self):
        """Vertex triples ``(T, 3)`` ``(i-1, i, i+1)`` of the vertices that bend."""
        count = len(self.points)
        middle = np.arange(count) if self.closed else np.arange(1, count - 1)
        return np.column_stack([(middle - 1) % count, middle, (middle + 1) % count])

    @property
    def voronoi_lengths(self):
        """Half the rest lengths of the edges next to each vertex, ``(N,)``."""
        lengths = np.zeros(len(self.points))
        edges = self.edges
        np.add.at(lengths, edges[:, 0], 0.5 * self.rest_lengths)
        np.add.at(lengths, edges[:, 1], 0.5 * self.rest_lengths)
        return lengths

    @property
    def fixed(self):
        """Boolean mask ``(N,)`` of the vertices the ends hold in place."""
        held = {"free": 0, "pinned": 1, "clamped": 2}
        fixed = np.zeros(len(self.points), dtype=bool)
        fixed[:held[self.start]] = True
        if held[self.end]:
            fixed[-held[self.end]:] = True
        return fixed

    @property
    def mean_radius(self):
        """Length-weighted mean radius."""
        weights = self.voronoi_lengths
        return float(np.sum(weights * self.radius) / np.sum(weights))

    def masses(self, density):
        """Mass lumped at each vertex (its Voronoi share of the edges' volume), ``(N,)``."""
        edges = self.edges
        volume = 0.5 * np.pi * self.radius[edges].mean(axis=1) ** 2 * self.rest_lengths
        masses = np.zeros(len(self.points))
        np.add.at(masses, edges[:, 0], density * volume)
        np.add.at(masses, edges[:, 1], density * volume)
        return masses


# -- sparse Hessian helpers ------------------------------------------------------------------
def block_hessian(vertices, blocks):
    """Triplets of a sparse Hessian from dense per-element blocks.

    Parameters
    ----------
    vertices : ndarray of int, shape (M, k)
        The ``k`` vertices of each element.
    blocks : ndarray, shape (M, 3k, 3k)
        Each element's Hessian over its vertices' coordinates, vertex-major.

    Returns
    -------
    rows, cols, values : ndarray
        Entries over the degrees of freedom ``3 * vertex + axis`` (duplicates add up).
    """
    vertices = np.asarray(vertices)
    dofs = (3 * vertices[:, :, None] + np.arange(3)).reshape(len(vertices), -1)
    size = dofs.shape[1]
    rows = np.repeat(dofs, size, axis=1).ravel()
    cols = np.tile(dofs, (1, size)).ravel()
    return rows, cols, np.asarray(blocks).reshape(-1)


def project_psd(blocks):
    """The nearest positive semi-definite matrices to symmetric ``blocks`` ``(M, n, n)``."""
    values, vectors = np.linalg.eigh(blocks)
    return (vectors * np.maximum(values, 0.0)[:, None, :]) @ np.swapaxes(vectors, 1, 2)


@dataclass(frozen=True, eq=False)
class Derivatives:
    """Energy, gradient and Hessian of a term at some points.

    The Hessian is positive semi-definite unless the exact one was asked for (then it may be
    indefinite).

    Attributes
    ----------
    energy : float
    gradient : ndarray, shape (N, 3)
    rows, cols, values : ndarray
        Sparse Hessian triplets over the degrees of freedom ``3 * vertex + axis``.
    low_rank : tuple of ndarray
        Dense vectors ``u`` of shape ``(3N,)``; the Hessian also holds ``u u^T`` for each.
    """

    energy: float
    gradient: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    values: np.ndarray
    low_rank: tuple = ()

    @classmethod
    def from_blocks(cls, energy, gradient, vertices, blocks, low_rank=()):
        """Build from per-element Hessian blocks (see :func:`block_hessian`)."""
        return cls(float(energy), gradient, *block_hessian(vertices, blocks), tuple(low_rank))

    @classmethod
    def linear(cls, energy, gradient):
        """A term with no curvature (a constant force)."""
        empty = np.zeros(0)
        return cls(float(energy), gradient, empty.astype(int), empty.astype(int), empty)


def _skew(vectors):
    """Cross-product matrices ``[v]x`` of vectors ``(M, 3)``."""
    x, y, z = vectors[:, 0], vectors[:, 1], vectors[:, 2]
    zero = np.zeros_like(x)
    return np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1),
                     np.stack([-y, x, zero], -1)], -2)


_EYE = np.eye(3)
#: (a, b) = (x_i - x_{i-1}, x_{i+1} - x_i) as a linear map of (x_{i-1}, x_i, x_{i+1}).
_BEND_MAP = np.block([[-_EYE, _EYE, 0 * _EYE], [0 * _EYE, -_EYE, _EYE]])
_EDGE_MAP = np.hstack([-_EYE, _EYE])
#: A vertex's holonomy-gradient contributions (-u, u - v, v) from (u, v) = kb/2 (1/|a|, 1/|b|).
_TWIST_MAP = np.block([[-_EYE, 0 * _EYE], [_EYE, -_EYE], [0 * _EYE, _EYE]])


# -- the rod's own energy ---------------------------------------------------------------------
def _bend_terms(a, b, order):
    """``|kb|**2 = 4 tan(phi / 2)**2`` of edge pairs ``(a, b)`` and, up to ``order``, its
    derivatives with respect to ``(a, b)`` (gradient ``(M, 6)``, Hessian ``(M, 6, 6)``).

    Value and gradient use the unit edges ``ua, ub``: ``|kb|**2 = 4 |ua - ub|**2 / |ua + ub|**2``
    (no cancellation when nearly straight). The Hessian uses ``4 (p - q) / (p + q)`` with
    ``p = |a||b|``, ``q = a.b``.
    """
    la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    ua, ub = a / la[:, None], b / lb[:, None]
    d, s = ua - ub, ua + ub
    d2 = np.einsum("ij,ij->i", d, d)
    s2 = np.maximum(np.einsum("ij,ij->i", s, s), 1e-24)  # zero only when folded back
    value = 4.0 * d2 / s2
    if order == 0:
        return value, None, None
    # d value / d ua and d value / d ub; each is normal to its unit edge, so dividing by the
    # edge's length gives the derivative with respect to the edge itself.
    scale = 8.0 / s2**2
    grad_a = scale[:, None] * (d * s2[:, None] - d2[:, None] * s) / la[:, None]
    grad_b = -scale[:, None] * (d * s2[:, None] + d2[:, None] * s) / lb[:, None]
    gradient = np.hstack([grad_a, grad_b])
    if order == 1:
        return value, gradient, None
    p, q = la * lb, np.einsum("ij,ij->i", a, b)
    s = p * 0.5 * s2  # p + q
    f_p, f_q = 8.0 * q / s**2, -8.0 * p / s**2
    grad_p = np.hstack([lb[:, None] * ua, la[:, None] * ub])
    grad_q = np.hstack([b, a])
    f_pp, f_qq, f_pq = -16.0 * q / s**3, 16.0 * p / s**3, 8.0 * (p - q) / s**3

    def outer(u, v):
        return u[:, :, None] * v[:, None, :]

    cross = outer(grad_p, grad_q)
    hessian = (f_pp[:, None, None] * outer(grad_p, grad_p)
               + f_qq[:, None, None] * outer(grad_q, grad_q)
               + f_pq[:, None, None] * (cross + np.swapaxes(cross, 1, 2)))
    eye = np.broadcast_to(_EYE, (len(a), 3, 3))
    hess_p = np.zeros_like(hessian)
    hess_p[:, :3, :3] = (lb / la)[:, None, None] * (eye - outer(ua, ua))
    hess_p[:, 3:, 3:] = (la / lb)[:, None, None] * (eye - outer(ub, ub))
    hess_p[:, :3, 3:] = outer(ua, ub)
    hess_p[:, 3:, :3] = outer(ub, ua)
    hessian += f_p[:, None, None] * hess_p
    hessian[:, :3, 3:] += f_q[:, None, None] * eye
    hessian[:, 3:, :3] += f_q[:, None, None] * eye
    return value, gradient, hessian


def _transports(tangents):
    """Parallel-transport rotations ``(E-1, 3, 3)`` taking each unit tangent to the next."""
    t0, t1 = tangents[:-1], tangents[1:]
    axis = np.cross(t0, t1)
    cos = np.einsum("ij,ij->i", t0, t1)
    scale = 1.0 / np.maximum(1.0 + cos, 1e-12)
    return (cos[:, None, None] * _EYE + _skew(axis)
            + scale[:, None, None] * np.einsum("mi,mj->mij", axis, axis))


def _chain_product(matrices):
    """``matrices[-1] @ ... @ matrices[0]`` by pairwise products (log depth)."""
    matrices = np.asarray(matrices)
    if len(matrices) == 0:
        return np.eye(3)
    while len(matrices) > 1:
        if len(matrices) % 2:
            matrices = np.concatenate([matrices, np.eye(3)[None]])
        matrices = matrices[1::2] @ matrices[0::2]
    return matrices[0]


def _perpendicular(direction):
    """A unit vector perpendicular to the unit vector ``direction``."""
    helper = _EYE[int(np.argmin(np.abs(direction)))]
    vector = np.cross(direction, helper)
    return vector / np.linalg.norm(vector)


def _signed_angle(source, target, axis):
    """Angle turning ``source`` to ``target`` about ``axis`` (all unit, both normal to it)."""
    return math.atan2(float(np.dot(np.cross(source, target), axis)), float(np.dot(source, target)))


class _Twist:
    """Uniform twist between two clamps (see the module notes)."""

    def __init__(self, rod, shear_modulus):
        tangents = self._tangents(rod.points)
        self.start_director = _perpendicular(tangents[0])
        self.end_director = _chain_product(_transports(tangents)) @ self.start_director
        self.end_twist = rod.end_twist
        polar = shear_modulus * np.pi * rod.radius**4 / 2.0
        inner = slice(1, len(rod.points) - 1)
        self.compliance = float(np.sum(rod.voronoi_lengths[inner] / polar[inner]))

    @staticmethod
    def _tangents(points):
        edges = np.diff(points, axis=0)
        return edges / np.linalg.norm(edges, axis=1)[:, None]

    def angle(self, points):
        """Total twist between the clamps."""
        tangents = self._tangents(points)
        carried = _chain_product(_transports(tangents)) @ self.start_director
        return self.end_twist + _signed_angle(carried, self.end_director, tangents[-1])

    def energy(self, points):
        return 0.5 * self.angle(points) ** 2 / self.compliance

    def derivatives(self, points, exact):
        """Energy, gradient ``(N, 3)``, the low-rank vector ``(3N,)`` of the Hessian's
        Gauss–Newton part and, if ``exact``, per-vertex blocks ``(N-2, 9, 9)`` of the rest
        (the twist times the holonomy's Hessian, which is banded), else None."""
        theta = self.angle(points)
        a, b = np.diff(points, axis=0)[:-1], np.diff(points, axis=0)[1:]
        la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
        cross = np.cross(a, b)
        denominator = la * lb + np.einsum("ij,ij->i", a, b)
        half = cross / denominator[:, None]  # kb / 2 at each interior vertex
        before, after = half / la[:, None], half / lb[:, None]
        grad_theta = np.zeros_like(points)  # holonomy gradient of the twist angle
        grad_theta[:-2] -= before
        grad_theta[2:] += after
        grad_theta[1:-1] += before - after
        energy = 0.5 * theta**2 / self.compliance
        gradient = theta / self.compliance * grad_theta
        low_rank = grad_theta.ravel() / math.sqrt(self.compliance)
        if not exact:
            return energy, gradient, low_rank, None
        # d(kb/2)/da and d(kb/2)/db, then of kb/(2|a|) and kb/(2|b|).
        ua, ub = a / la[:, None], b / lb[:, None]
        d_a = ((-_skew(b)) - half[:, :, None] * (lb[:, None] * ua + b)[:, None, :]) \
            / denominator[:, None, None]
        d_b = (_skew(a) - half[:, :, None] * (la[:, None] * ub + a)[:, None, :]) \
            / denominator[:, None, None]
        jacobian = np.zeros((len(a), 6, 6))  # d(before, after) / d(a, b)
        jacobian[:, :3, :3] = (d_a - half[:, :, None] * ua[:, None, :] / la[:, None, None]) \
            / la[:, None, None]
        jacobian[:, :3, 3:] = d_b / la[:, None, None]
        jacobian[:, 3:, :3] = d_a / lb[:, None, None]
        jacobian[:, 3:, 3:] = (d_b - half[:, :, None] * ub[:, None, :] / lb[:, None, None]) \
            / lb[:, None, None]
        blocks = _TWIST_MAP @ jacobian @ _BEND_MAP
        blocks = 0.5 * (blocks + np.swapaxes(blocks, 1, 2))  # their sum is symmetric
        return energy, gradient, low_rank, theta / self.compliance * blocks


class ElasticEnergy:
    """Stretching, bending and (with two clamped ends) twisting energy of a rod.

    Parameters
    ----------
    rod : Rod
    settings : RodSettings, optional
        Only the material is used.
    """

    name = "elastic"

    def __init__(self, rod, settings=RodSettings()):
        modulus = settings.youngs_modulus
        self.edges, self.bends = rod.edges, rod.bends
        self.rest = rod.rest_lengths
        edge_radius = rod.radius[self.edges].mean(axis=1)
        self.stretch = modulus * np.pi * edge_radius**2
        inertia = np.pi * rod.radius[self.bends[:, 1]] ** 4 / 4.0
        rest, middle = rod.rest_lengths, self.bends[:, 1]
        self.bend = modulus * inertia / (rest[(middle - 1) % len(rest)] + rest[middle % len(rest)])
        clamped = not rod.closed and rod.start == rod.end == "clamped"
        self.twist = _Twist(rod, settings.shear_modulus) if clamped else None

    def model(self, points):
        """The energy needs no refreshing: itself."""
        return self

    def _stretching(self, points):
        edge = points[self.edges[:, 1]] - points[self.edges[:, 0]]
        length = np.linalg.norm(edge, axis=1)
        strain = length / self.rest - 1.0
        return 0.5 * np.sum(self.stretch * strain**2 * self.rest), edge, length, strain

    def _bending(self, points, order):
        a = points[self.bends[:, 1]] - points[self.bends[:, 0]]
        b = points[self.bends[:, 2]] - points[self.bends[:, 1]]
        value, gradient, hessian = _bend_terms(a, b, order)
        return np.sum(self.bend * value), gradient, hessian

    def energy(self, points):
        """Total elastic energy at ``points`` ``(N, 3)``."""
        energy = self._stretching(points)[0] + self._bending(points, 0)[0]
        if self.twist is not None:
            energy += self.twist.energy(points)
        return float(energy)

    def derivatives(self, points, *, exact=False):
        """:class:`Derivatives` at ``points``; the Hessian is exact (``exact``, possibly
        indefinite; the twist's stays Gauss–Newton) or projected per element onto positive
        semi-definite matrices."""
        energy, edge, length, strain = self._stretching(points)
        bend_energy, bend_grad, bend_hess = self._bending(points, 2)
        energy += bend_energy
        unit = edge / length[:, None]
        force = (self.stretch * strain)[:, None] * unit  # dE/de per edge
        gradient = np.zeros_like(points)
        np.add.at(gradient, self.edges[:, 0], -force)
        np.add.at(gradient, self.edges[:, 1], force)
        along = self.stretch / self.rest
        across = self.stretch * strain / length
        if not exact:
            across = np.maximum(across, 0.0)  # PSD: drop the compression part
        outer = unit[:, :, None] * unit[:, None, :]
        edge_hess = along[:, None, None] * outer + across[:, None, None] * (_EYE - outer)
        edge_blocks = _EDGE_MAP.T @ edge_hess @ _EDGE_MAP
        bend_grad = self.bend[:, None] * bend_grad
        for k, sign_a, sign_b in ((0, -1, 0), (1, 1, -1), (2, 0, 1)):
            np.add.at(gradient, self.bends[:, k],
                      sign_a * bend_grad[:, :3] + sign_b * bend_grad[:, 3:])
        bend_hess = self.bend[:, None, None] * bend_hess
        if not exact:
            bend_hess = project_psd(bend_hess)
        bend_blocks = _BEND_MAP.T @ bend_hess @ _BEND_MAP
        low_rank = ()
        if self.twist is not None:
            twist_energy, twist_grad, twist_vector, twist_blocks = \
                self.twist.derivatives(points, exact)
            energy += twist_energy
            gradient += twist_grad
            low_rank = (twist_vector,)
            if twist_blocks is not None:
                bend_blocks = bend_blocks + twist_blocks  # same vertex triples
        rows_e, cols_e, vals_e = block_hessian(self.edges, edge_blocks)
        rows_b, cols_b, vals_b = block_hessian(self.bends, bend_blocks)
        return Derivatives(float(energy), gradient, np.concatenate([rows_e, rows_b]),
                           np.concatenate([cols_e, cols_b]), np.concatenate([vals_e, vals_b]),
                           low_rank)


class Load:
    """Constant forces on the vertices (point loads, gravity): energy ``-sum F_i . x_i``.

    Parameters
    ----------
    forces : array_like, shape (N, 3)
        Newtons.
    """

    name = "load"

    def __init__(self, forces):
        self.forces = as_points(forces, "forces")

    @classmethod
    def gravity(cls, rod, settings):
        """The rod's weight under ``settings.gravity`` (zero forces if None)."""
        if settings.gravity is None:
            return cls(np.zeros_like(rod.points))
        return cls(rod.masses(settings.density)[:, None] * np.asarray(settings.gravity))

    def model(self, points):
        """Constant: itself."""
        return self

    def energy(self, points):
        """Potential energy of the forces at ``points``."""
        return -float(np.sum(self.forces * points))

    def derivatives(self, points, *, exact=False):
        """:class:`Derivatives` at ``points`` (no curvature)."""
        return Derivatives.linear(self.energy(points), -self.forces)


class EndMoment:
    """A constant moment about a fixed axis on one edge (a dead couple at a free end).

    Energy ``-M theta``, with ``theta`` the angle of the edge, projected on the plane normal to
    ``axis``, measured from ``reference`` about ``axis``. ``theta`` lies in ``(-pi, pi]``: pick
    ``reference`` near the expected final direction of the edge so that the edge never turns
    through the opposite direction.

    Parameters
    ----------
    moment : float
        N m, turning the edge counter-clockwise about ``axis``.
    axis, reference : array_like, shape (3,)
        The moment's axis and the direction the angle is measured from (made normal to it).
    edge : tuple of int, optional
        The edge's two vertices; the last edge by default.
    """

    name = "moment"

    def __init__(self, *, moment, axis, reference, edge=(-2, -1)):
        axis = np.asarray(axis, dtype=np.float64)
        if axis.shape != (3,) or not np.linalg.norm(axis) > 0:
            raise ValueError("axis must be a non-zero 3-vector")
        self.axis = axis / np.linalg.norm(axis)
        reference = np.asarray(reference, dtype=np.float64)
        reference = reference - np.dot(reference, self.axis) * self.axis
        if not np.linalg.norm(reference) > 0:
            raise ValueError("reference must not be parallel to axis")
        self.reference = reference / np.linalg.norm(reference)
        self.moment = float(moment)
        self.edge = tuple(int(v) for v in edge)

    def model(self, points):
        """Constant: itself."""
        return self

    def _planar(self, points):
        edge = points[self.edge[1]] - points[self.edge[0]]
        return edge - np.dot(edge, self.axis) * self.axis

    def angle(self, points):
        """The edge's angle from ``reference`` about ``axis``."""
        return _signed_angle(self.reference, self._planar(points), self.axis)

    def energy(self, points):
        """``-M theta``."""
        return -self.moment * self.angle(points)

    def derivatives(self, points, *, exact=False):
        """:class:`Derivatives`; the Hessian is exact or its PSD part."""
        planar = self._planar(points)
        norm2 = float(np.dot(planar, planar))
        turn = np.cross(self.axis, planar)
        grad_edge = -self.moment * turn / norm2
        gradient = np.zeros_like(points)
        vertices = np.array(self.edge) % len(points)
        gradient[vertices[0]] -= grad_edge
        gradient[vertices[1]] += grad_edge
        # Hessian of theta with respect to the edge: -(n u^T + u n^T) / |w|^2, with u the
        # projected edge's direction and n = axis x u (theta is harmonic in the plane).
        unit, normal = planar / math.sqrt(norm2), turn / math.sqrt(norm2)
        sym = np.outer(unit, normal) + np.outer(normal, unit)
        hess_edge = self.moment / norm2 * sym
        if not exact:
            hess_edge = project_psd(hess_edge[None])[0]
        blocks = (_EDGE_MAP.T @ hess_edge @ _EDGE_MAP)[None]
        return Derivatives.from_blocks(self.energy(points), gradient, vertices[None], blocks)


# -- the solver -------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Equilibrium:
    """Where the energy minimisation ended.

    Attributes
    ----------
    points : ndarray, shape (N, 3)
    energy : float
        Total energy there.
    energies : dict
        Energy per term name.
    iterations : int
        Newton iterations taken.
    converged : bool
        The last full Newton step was below the step tolerance (or, when refreshed models
        cycle between states and the energy stops falling, within ten times it).
    """

    points: np.ndarray
    energy: float
    energies: dict
    iterations: int
    converged: bool


class _Solver:
    """One Newton iteration's linear algebra over the free degrees of freedom.

    A matrix whose entries all lie within :data:`_BAND` of the diagonal (an open rod without
    long-range terms) is factored by banded Cholesky, which also tells an indefinite matrix
    (``LinAlgError``); any other by sparse LU with a fill-reducing ordering.
    """

    def __init__(self, free_dofs, size):
        self.free = free_dofs
        self.index = np.full(size, -1)
        self.index[free_dofs] = np.arange(len(free_dofs))

    def _triplets(self, parts):
        rows = self.index[np.concatenate([p.rows for p in parts])]
        cols = self.index[np.concatenate([p.cols for p in parts])]
        values = np.concatenate([p.values for p in parts])
        keep = (rows >= 0) & (cols >= 0)
        return rows[keep], cols[keep], values[keep]

    def _factor(self, rows, cols, values):
        """A function solving with the matrix (plus a tiny regularisation)."""
        n = len(self.free)
        diagonal = np.bincount(rows[rows == cols], values[rows == cols], minlength=n)
        regular = 1e-10 * max(float(np.abs(diagonal).max(initial=0.0)), 1e-300)
        band = int(np.abs(rows - cols).max(initial=0))
        if band <= _BAND:
            lower = rows >= cols
            flat = np.bincount((rows[lower] - cols[lower]) * n + cols[lower], values[lower],
                               minlength=(band + 1) * n).reshape(band + 1, n)
            flat[0] += regular
            factor = cholesky_banded(flat, lower=True)
            return lambda rhs: cho_solve_banded((factor, True), rhs)
        matrix = csc_matrix((np.concatenate([values, np.full(n, regular)]),
                             (np.concatenate([rows, np.arange(n)]),
                              np.concatenate([cols, np.arange(n)]))), shape=(n, n))
        factor = splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                      options={"SymmetricMode": True})
        return factor.solve

    def direction(self, parts, gradient):
        """The Newton direction ``-H^-1 g`` (full-size, zero on held dofs).

        Raises
        ------
        RuntimeError, numpy.linalg.LinAlgError
            The matrix is singular (or, for banded Cholesky, not positive definite).
        """
        solve = self._factor(*self._triplets(parts))
        g = gradient.ravel()[self.free]
        step = -solve(g)
        vectors = [u[self.free] for p in parts for u in p.low_rank]
        if vectors:  # Woodbury: (A + U U^T)^-1
            u = np.column_stack(vectors)
            solved = solve(u)
            small = np.eye(u.shape[1]) + u.T @ solved
            step -= solved @ np.linalg.solve(small, u.T @ step)
        full = np.zeros(len(self.index))
        full[self.free] = step
        return full.reshape(-1, 3)


def minimise_energy(terms, points, *, fixed=None, length_scale, settings=RodSettings(),
                    progress=None, cancel=None):
    """Minimise a sum of energy terms by Newton's method with a line search.

    Parameters
    ----------
    terms : sequence
        Energy terms (see the module notes): each has ``name`` and ``model(points)``.
    points : array_like, shape (N, 3)
        Start.
    fixed : array_like of bool, shape (N,), optional
        Vertices that do not move.
    length_scale : float
        The length tolerances are relative to (the rod's mean radius).
    settings : RodSettings, optional
        ``max_iterations``, ``step_tolerance`` and ``max_step`` are used.
    progress : callable, optional
        ``progress(fraction, message)``, once per iteration (fraction of ``max_iterations``).
    cancel : threading.Event, optional
        Checked every iteration; raises :class:`~engine.errors.Cancelled` when set.

    Returns
    -------
    Equilibrium
    """
    x = as_points(points)
    if not length_scale > 0:
        raise ValueError("length_scale must be positive")
    fixed = np.zeros(len(x), dtype=bool) if fixed is None else np.asarray(fixed, dtype=bool)
    free_dofs = np.flatnonzero(np.repeat(~fixed, 3))
    solver = _Solver(free_dofs, x.size)
    tolerance = settings.step_tolerance * length_scale
    limit = settings.max_step * length_scale
    converged, iterations, largest = False, 0, np.inf
    best = _Lowest()
    for iterations in range(1, settings.max_iterations + 1):
        check_cancel(cancel, "the rod solve")
        models = [term.model(x) for term in terms]
        if best.stalled(sum(model.energy(x) for model in models), x, iterations):
            # Refreshed models (nearest points) cycle between a few states: settled if their
            # steps are small.
            log.debug("no progress for %d iterations: stopping", _STALL)
            x, converged = best.points, largest <= _SETTLED * tolerance
            break
        x, largest, decrease = _newton_step(models, x, fixed, solver, limit)
        log.debug("iteration %d: step %.3g r", iterations, largest / length_scale)
        if progress is not None:
            progress(iterations / settings.max_iterations,
                     f"rod: iteration {iterations}, step {largest / length_scale:.2g} r")
        if largest <= tolerance:
            converged = True
            break
        if decrease is not None:  # no step was accepted
            # Converged if the decrease Newton promises is below what the energy resolves.
            converged = decrease <= _RESOLUTION * max(abs(best.energy), 1e-300)
            log.debug("line search failed at iteration %d (step %.3g r, decrease %.3g)",
                      iterations, largest / length_scale, decrease)
            break
    models = [term.model(x) for term in terms]
    energies = {}
    for term, model in zip(terms, models):
        energies[term.name] = energies.get(term.name, 0.0) + model.energy(x)
    return Equilibrium(points=read_only(x), energy=float(sum(energies.values())),
                       energies=energies, iterations=iterations, converged=converged)


class _Lowest:
    """The lowest energy seen so far, to notice when refreshed models stop lowering it."""

    def __init__(self):
        self.energy, self.points, self.iteration = np.inf, None, 0

    def stalled(self, energy, points, iteration):
        """Record ``energy`` at ``points``; True after :data:`_STALL` iterations without a
        new lowest."""
        if self.points is None or energy < self.energy - 1e-12 * abs(self.energy):
            self.energy, self.points, self.iteration = energy, points, iteration
            return False
        return iteration - self.iteration >= _STALL


def _newton_step(models, x, fixed, solver, limit):
    """One Newton iteration from ``x``: the exact Hessian's step if it passes the Armijo test
    at once, else the projected (positive semi-definite) Hessian's step with a line search.

    Returns the new points, the largest vertex move of the full step and, when no step was
    accepted, the energy decrease the last Newton model promised (None otherwise).
    """
    largest, decrease = np.inf, np.inf
    for exact in (True, False):
        parts = [model.derivatives(x, exact=exact) for model in models]
        energy = sum(p.energy for p in parts)
        gradient = sum(p.gradient for p in parts)
        gradient[fixed] = 0.0
        try:
            step = solver.direction(parts, gradient)
        except (RuntimeError, np.linalg.LinAlgError):  # a singular or indefinite exact Hessian
            continue
        largest = float(np.linalg.norm(step, axis=1).max(initial=0.0))
        slope = float(np.sum(gradient * step))
        if not np.isfinite(largest) or (slope >= 0.0 and largest > 0.0):
            continue
        if largest == 0.0:
            return x, 0.0, None
        alpha = min(1.0, limit / largest)
        trial, accepted = _line_search(models, x, step, energy, slope, alpha,
                                       halvings=4 if exact else 40)
        if accepted:
            return trial, largest, None
        decrease = -0.5 * slope
    return x, largest, decrease


def _line_search(models, x, step, energy, slope, alpha, halvings=40):
    """Backtracking Armijo search along ``step`` from ``alpha``; returns (points, accepted)."""
    for _ in range(halvings):
        trial = x + alpha * step
        value = sum(model.energy(trial) for model in models)
        if np.isfinite(value) and value <= energy + _ARMIJO * alpha * slope:
            return trial, True
        alpha *= 0.5
    return x, False


def solve_rod(rod, *, settings=RodSettings(), forces=None, terms=(), initial=None,
              progress=None, cancel=None):
    """Static equilibrium of a rod under gravity, forces and extra energy terms.

    Parameters
    ----------
    rod : Rod
    settings : RodSettings, optional
    forces : array_like, shape (N, 3), optional
        Constant point forces (N), added to gravity.
    terms : sequence, optional
        Extra energy terms (e.g. :class:`EndMoment`, or a fit's data terms).
    initial : array_like, shape (N, 3), optional
        Start; the reference points by default. Held vertices stay at their reference places.
    progress, cancel : optional
        See :func:`minimise_energy`.

    Returns
    -------
    Equilibrium
    """
    if not isinstance(rod, Rod):
        raise ValueError("rod must be a Rod")
    start = rod.points.copy() if initial is None else as_points(initial, "initial")
    if start.shape != rod.points.shape:
        raise ValueError("initial must have the rod's shape")
    fixed = rod.fixed
    start[fixed] = rod.points[fixed]
    load = Load.gravity(rod, settings)
    if forces is not None:
        load = Load(load.forces + as_points(forces, "forces").reshape(rod.points.shape))
    all_terms = [ElasticEnergy(rod, settings), load, *terms]
    return minimise_energy(all_terms, start, fixed=fixed, length_scale=rod.mean_radius,
                           settings=settings, progress=progress, cancel=cancel)
