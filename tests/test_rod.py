"""engine.stages.rod: discrete elastic rods against beam theory, exact derivatives and
robustness."""

import threading

import numpy as np
import pytest

from conftest import finite_gradient

from engine.errors import Cancelled
from engine.stages.rod import Derivatives, ElasticEnergy, EndMoment, Rod, RodSettings, solve_rod


def straight_rod(count, spacing, radius, **ends):
    """A rod along +x whose clamped first edge is centred on the origin."""
    x = (np.arange(count) - 0.5) * spacing
    return Rod(np.column_stack([x, 0 * x, 0 * x]), radius, **ends)


def dense_hessian(derivatives, count):
    hessian = np.zeros((3 * count, 3 * count))
    np.add.at(hessian, (derivatives.rows, derivatives.cols), derivatives.values)
    for vector in derivatives.low_rank:
        hessian += np.outer(vector, vector)
    return hessian


class Planar:
    """Keeps a rod in the plane z = 0 (a stiff spring on z), for 2D elastica."""

    name = "planar"

    def __init__(self, stiffness):
        self.stiffness = stiffness

    def model(self, points):
        return self

    def energy(self, points):
        return 0.5 * self.stiffness * float(np.sum(points[:, 2] ** 2))

    def derivatives(self, points, *, exact=False):
        gradient = np.zeros_like(points)
        gradient[:, 2] = self.stiffness * points[:, 2]
        blocks = np.zeros((len(points), 3, 3))
        blocks[:, 2, 2] = self.stiffness
        return Derivatives.from_blocks(self.energy(points), gradient,
                                       np.arange(len(points))[:, None], blocks)


def test_cantilever_tip_load_matches_euler_bernoulli():
    radius, modulus, spacing, count = 0.002, 1e7, 0.004, 60
    rod = straight_rod(count, spacing, radius, start="clamped")
    length = (count - 1.5) * spacing  # from the clamp (middle of the first edge) to the tip
    inertia = np.pi * radius**4 / 4
    load = 0.01 * 3 * modulus * inertia / length**2  # tip deflection 1% of the length
    forces = np.zeros((count, 3))
    forces[-1, 2] = -load
    result = solve_rod(rod, settings=RodSettings(youngs_modulus=modulus), forces=forces)
    expected = load * length**3 / (3 * modulus * inertia)
    assert result.converged
    assert result.iterations <= 10  # Newton: quadratic convergence
    assert -result.points[-1, 2] == pytest.approx(expected, rel=0.01)
    np.testing.assert_allclose(result.points[:2], rod.points[:2])  # the clamp held


def test_cantilever_under_own_weight_matches_euler_bernoulli():
    radius, modulus, spacing, count, density = 0.002, 1e10, 0.004, 61, 1300.0
    rod = straight_rod(count, spacing, radius, start="clamped")
    length = (count - 1.5) * spacing
    settings = RodSettings(youngs_modulus=modulus, density=density, gravity=(0, 0, -9.81))
    result = solve_rod(rod, settings=settings)
    weight = density * np.pi * radius**2 * 9.81  # per unit length
    expected = weight * length**4 / (8 * modulus * np.pi * radius**4 / 4)
    assert result.converged
    assert -result.points[-1, 2] == pytest.approx(expected, rel=0.01)


@pytest.mark.parametrize("turn", [1.5 * np.pi, 1.9 * np.pi])
def test_terminal_moment_bends_rod_into_circle(turn):
    radius, modulus, spacing, count = 0.002, 1e7, 0.004, 80
    rod = straight_rod(count, spacing, radius, start="clamped")
    length = (count - 1.5) * spacing
    inertia = np.pi * radius**4 / 4
    moment = modulus * inertia * turn / length
    halfway = np.array([np.cos(turn / 2), np.sin(turn / 2), 0.0])  # far from the angle's cut
    terms = [EndMoment(moment=moment, axis=(0, 0, 1), reference=halfway), Planar(modulus * radius)]
    result = solve_rod(rod, settings=RodSettings(youngs_modulus=modulus), terms=terms)
    assert result.converged
    edges = np.diff(result.points, axis=0)
    angles = np.unwrap(np.arctan2(edges[:, 1], edges[:, 0]))
    turning = np.diff(angles)
    assert angles[-1] == pytest.approx(turn, rel=0.01)
    assert np.std(turning) < 1e-6 * np.mean(turning)  # constant curvature
    bent = result.points[1:, :2]  # every vertex past the clamp lies on one circle...
    design = np.column_stack([2 * bent, np.ones(len(bent))])
    (cx, cy, c), *_ = np.linalg.lstsq(design, np.sum(bent**2, axis=1), rcond=None)
    circle = np.sqrt(c + cx**2 + cy**2)
    np.testing.assert_allclose(np.hypot(*(bent - [cx, cy]).T), circle, rtol=1e-6)
    assert circle == pytest.approx(modulus * inertia / moment, rel=0.01)  # ... of radius EI/M


def test_pinned_ends_turn_freely_and_clamped_ends_do_not():
    count, spacing, radius = 41, 0.004, 0.002
    settings = RodSettings(youngs_modulus=1e7, gravity=(0, 0, -9.81))
    slopes = {}
    for ends in ("pinned", "clamped"):
        rod = straight_rod(count, spacing, radius, start=ends, end=ends)
        result = solve_rod(rod, settings=settings)
        assert result.converged
        held = rod.fixed
        np.testing.assert_allclose(result.points[held], rod.points[held])
        sag = result.points[:, 2]
        np.testing.assert_allclose(sag, sag[::-1], atol=1e-9 * spacing)  # symmetric
        assert np.argmin(sag) in (count // 2, count // 2 - 1, count // 2 + 1)
        first = result.points[1] - result.points[0]
        slopes[ends] = abs(first[2]) / np.linalg.norm(first)
    assert slopes["clamped"] < 1e-12 < 0.01 < slopes["pinned"]


def test_closed_ring_relaxes_to_a_circle():
    t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    ellipse = 0.05 * np.column_stack([1.3 * np.cos(t), 0.8 * np.sin(t), 0 * t])
    rod = Rod(ellipse, 0.002, closed=True)
    result = solve_rod(rod)
    assert result.converged
    distance = np.linalg.norm(result.points - result.points.mean(axis=0), axis=1)
    assert np.std(distance) < 1e-3 * np.mean(distance)
    assert np.mean(distance) == pytest.approx(rod.rest_lengths.sum() / (2 * np.pi), rel=1e-3)


def test_clamped_twisted_rod_buckles_past_greenhills_load():
    radius, modulus, spacing, count = 0.002, 1e10, 0.004, 61
    x = np.arange(count) * spacing
    bowed = np.column_stack([x, 1e-3 * spacing * np.sin(np.pi * x / x[-1]), 0 * x])
    settings = RodSettings(youngs_modulus=modulus)
    inertia = np.pi * radius**4 / 4
    stiffness = settings.shear_modulus * 2 * inertia  # G J
    # Clamped-clamped Greenhill: a twisting moment of 2.861 pi E I / L buckles the rod.
    critical = 2.861 * np.pi * modulus * inertia / stiffness
    lateral = {}
    for fraction in (0.8, 1.2):
        rod = Rod(bowed, radius, start="clamped", end="clamped", end_twist=fraction * critical)
        result = solve_rod(rod, settings=settings)
        lateral[fraction] = np.abs(result.points[:, 1:]).max() / radius
        twisted_straight = stiffness * (fraction * critical) ** 2 / (2 * (x[-1] - spacing))
        if fraction < 1:
            assert result.converged
            assert result.energy == pytest.approx(twisted_straight, rel=1e-3)
        else:
            assert result.energy < (1 - 1e-6) * twisted_straight  # twist traded for writhe
    assert lateral[0.8] < 0.01
    assert lateral[1.2] > 0.3


@pytest.mark.parametrize("closed, ends", [(False, ("free", "free")), (True, ("free", "free")),
                                          (False, ("clamped", "clamped"))])
def test_elastic_gradient_and_hessian_are_exact(closed, ends):
    rng = np.random.default_rng(1)
    count = 10
    s = np.linspace(0, 3, count)
    reference = np.column_stack([s, 0.3 * np.sin(s), 0.1 * s**2])
    rod = Rod(reference, np.linspace(0.04, 0.06, count), closed=closed, start=ends[0],
              end=ends[1], end_twist=0.7)
    energy = ElasticEnergy(rod, RodSettings(youngs_modulus=1e3))
    points = reference + 0.05 * rng.normal(size=reference.shape)
    points[rod.fixed] = reference[rod.fixed]
    free = np.repeat(~rod.fixed, 3)
    derivatives = energy.derivatives(points, exact=True)
    assert derivatives.energy == pytest.approx(energy.energy(points))
    numeric = finite_gradient(energy.energy, points)
    np.testing.assert_allclose(derivatives.gradient.ravel()[free], numeric.ravel()[free],
                               atol=1e-6 * np.abs(numeric).max())
    hessian = dense_hessian(derivatives, count)[np.ix_(free, free)]
    numeric = np.zeros_like(hessian)
    step = 1e-6
    for column, dof in enumerate(np.flatnonzero(free)):
        delta = np.zeros(points.size)
        delta[dof] = step
        delta = delta.reshape(-1, 3)
        change = (energy.derivatives(points + delta).gradient
                  - energy.derivatives(points - delta).gradient) / (2 * step)
        numeric[:, column] = change.ravel()[free]
    np.testing.assert_allclose(hessian, numeric, atol=1e-6 * np.abs(numeric).max())
    projected = dense_hessian(energy.derivatives(points), count)
    assert np.linalg.eigvalsh(projected).min() > -1e-9 * np.abs(projected).max()


def test_end_moment_gradient_is_exact():
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.2, 0.1], [1.5, 0.9, -0.2]])
    moment = EndMoment(moment=2.0, axis=(0.1, 0.2, 1.0), reference=(1.0, 0.0, 0.0))
    numeric = finite_gradient(moment.energy, points)
    np.testing.assert_allclose(moment.derivatives(points).gradient, numeric, atol=1e-8)


@pytest.mark.parametrize("radius", [0.0005, 0.002, 0.01])
@pytest.mark.parametrize("modulus", [1e6, 1e8, 1e9])
def test_no_blow_up_across_radius_and_stiffness(radius, modulus):
    count = 60
    rod = straight_rod(count, radius, radius, start="clamped")
    settings = RodSettings(youngs_modulus=modulus, gravity=(0, 0, -9.81))
    result = solve_rod(rod, settings=settings)
    assert result.converged and np.all(np.isfinite(result.points))
    strain = np.linalg.norm(np.diff(result.points, axis=0), axis=1) / radius - 1
    assert np.abs(strain).max() < 0.01  # nearly inextensible, even when it hangs
    drop = -result.points[-1, 2]
    assert 0 < drop < count * radius
    assert np.all(np.diff(result.points[1:, 2]) <= 1e-12)  # sags monotonically


def test_rod_rejects_bad_input():
    points = np.column_stack([np.arange(5.0), np.zeros(5), np.zeros(5)])
    with pytest.raises(ValueError, match="radius"):
        Rod(points, 0.0)
    with pytest.raises(ValueError, match="closed"):
        Rod(points, 0.1, closed=True, start="clamped")
    with pytest.raises(ValueError, match="start"):
        Rod(points, 0.1, start="glued")
    with pytest.raises(ValueError, match="rest_lengths"):
        Rod(points, 0.1, rest_lengths=[1.0, 1.0])
    with pytest.raises(ValueError, match="coincide"):
        Rod(np.vstack([points[:2], points[1:]]), 0.1)
    with pytest.raises(ValueError, match="youngs_modulus"):
        RodSettings(youngs_modulus=-1.0)


def test_solve_honours_cancel_and_reports_progress():
    rod = straight_rod(30, 0.004, 0.002, start="clamped")
    settings = RodSettings(gravity=(0, 0, -9.81))
    reports = []
    solve_rod(rod, settings=settings, progress=lambda fraction, message: reports.append(fraction))
    assert reports and all(0 < f <= 1 for f in reports)
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(Cancelled):
        solve_rod(rod, settings=settings, cancel=cancel)
