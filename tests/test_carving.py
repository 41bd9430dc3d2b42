"""Voxel carving (§3.2) on ground-truth scenes: coarse to fine is exact, the hull holds the
cable."""

import threading
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine import Cancelled
from engine.stages.carving import CarvingSettings, carve, scene_region
from engine.stages.segmentation import cable_width, junction_map
from engine.synthetic.scene import SceneSpec, make_scene


@pytest.fixture(scope="module")
def scene():
    """12 views at 480x360 of a 2-crossing table scene with its exact masks and junctions."""
    scene = make_scene(SceneSpec(crossings=2, seed=3, views=12, width=480, height=360,
                                 radius=0.006))
    junctions = [junction_map(mask, cable_width(mask)) for mask in scene.masks]
    return scene, junctions


@pytest.fixture(scope="module")
def grid(scene):
    scene, junctions = scene
    return carve(scene.cameras, scene.masks, junctions)


def _occupied_world(grid):
    return {tuple(np.round(p / grid.voxel_size).astype(int)) for p in grid.occupied_points()}


def test_coarse_to_fine_equals_a_full_carve(scene):
    scene, _ = scene
    truth = scene.truth
    lower = truth.centreline.min(axis=0) - 12 * truth.radius
    side = float((truth.centreline.max(axis=0) - lower).max() + 12 * truth.radius)
    settings = CarvingSettings(voxels_per_radius=1.5, root_cells=4, min_piece_length=0.0)
    coarse = carve(scene.cameras, scene.masks, radius=truth.radius, region=(lower, side),
                   settings=settings)
    full = carve(scene.cameras, scene.masks, radius=truth.radius, region=(lower, side),
                 settings=CarvingSettings(voxels_per_radius=1.5, root_cells=4,
                                          min_piece_length=0.0, coarse_to_fine=False))
    # the same whether the distance maps are kept between levels or not, on any thread count
    again = carve(scene.cameras, scene.masks, radius=truth.radius, region=(lower, side),
                  settings=replace(settings, cache_mb=0.0, threads=1))
    np.testing.assert_array_equal(again.index, coarse.index)
    assert coarse.voxel_size == pytest.approx(full.voxel_size)
    assert len(coarse) > 1000
    assert coarse.shape == full.shape
    np.testing.assert_allclose(coarse.origin, full.origin, atol=1e-12)
    np.testing.assert_array_equal(coarse.index, full.index)
    np.testing.assert_array_equal(coarse.visible, full.visible)
    np.testing.assert_array_equal(coarse.agreement, full.agreement)


def test_the_hull_holds_the_whole_cable_and_is_fat(scene, grid):
    scene, _ = scene
    truth = scene.truth
    assert grid.radius == pytest.approx(truth.radius, rel=0.1)
    assert grid.voxel_size == pytest.approx(grid.radius / CarvingSettings().voxels_per_radius)
    points = grid.occupied_points()
    # every point of the true centreline is inside the hull (within half a voxel diagonal)
    gap, _ = cKDTree(points).query(truth.centreline)
    assert gap.max() <= 0.87 * grid.voxel_size
    # and the hull hugs the cable: fat (a visual hull, tall where views look along the cable)
    # but not a box
    distance, _ = cKDTree(truth.centreline).query(points)
    assert 0.5 * truth.radius < np.median(distance) < 4 * truth.radius
    assert np.percentile(distance, 90) < 15 * truth.radius


def test_junction_voxels_sit_at_the_crossings(scene, grid):
    scene, _ = scene
    truth = scene.truth
    junctions = grid.occupied_points(grid.junction)
    crossings = np.array([truth.crossing_position(c) for c in truth.crossings])
    near, _ = cKDTree(junctions).query(crossings)
    assert near.max() < 2 * truth.radius  # every crossing has junction voxels
    far, _ = cKDTree(crossings).query(junctions)
    assert np.mean(far > 6 * truth.radius) < 0.05  # and they are nowhere else


def test_masks_can_be_loaded_lazily(scene, grid):
    scene, junctions = scene
    lazy = carve(scene.cameras, [lambda m=m: m for m in scene.masks],
                 [lambda j=j: j for j in junctions])
    np.testing.assert_array_equal(lazy.index, grid.index)
    np.testing.assert_array_equal(lazy.junction, grid.junction)


def test_the_region_comes_from_the_cameras(scene):
    scene, _ = scene
    lower, side = scene_region(scene.cameras)
    points = scene.truth.centreline
    assert (points >= lower).all() and (points <= lower + side).all()


def test_bad_input_and_cancel(scene):
    scene, _ = scene
    with pytest.raises(ValueError, match="masks for"):
        carve(scene.cameras, scene.masks[:-1])
    with pytest.raises(ValueError, match="is 10x10, its image 480x360"):
        carve(scene.cameras, [np.zeros((10, 10), bool)] * len(scene.cameras))
    with pytest.raises(ValueError, match="no view shows the cable"):
        carve(scene.cameras, [np.zeros((360, 480), bool)] * len(scene.cameras))
    cancel = threading.Event()
    calls = []

    def progress(fraction, message):
        calls.append(fraction)
        if fraction > 0.3:
            cancel.set()

    with pytest.raises(Cancelled):
        carve(scene.cameras, scene.masks, progress=progress, cancel=cancel)
    assert calls and max(calls) < 0.6


def test_masks_that_take_in_everything_stop_at_the_memory_budget(scene):
    """Masks of the whole frame occupy the whole region: the carve stops with a clear error
    before it allocates more than its budget (it used to run the machine out of memory)."""
    import tracemalloc

    from engine.errors import ReconstructionError

    scene, _ = scene
    everything = [np.ones_like(mask) for mask in scene.masks]
    tracemalloc.start()  # NumPy reports its arrays to it
    try:
        with pytest.raises(ReconstructionError,
                           match=r"carving would need .* GB .* budget of 0\.2 GB"):
            carve(scene.cameras, everything, radius=scene.truth.radius,
                  settings=CarvingSettings(memory_mb=200))
        peak = tracemalloc.get_traced_memory()[1] / 2 ** 20  # MB
    finally:
        tracemalloc.stop()
    assert peak < 300
    # the cable's own masks fit well within that budget
    grid = carve(scene.cameras, scene.masks, radius=scene.truth.radius,
                 settings=CarvingSettings(memory_mb=200))
    assert len(grid)


def test_past_the_budget_the_carve_is_coarser_and_says_so(scene):
    from engine.stages.carving import _CORE_BYTES, _VOXEL_BYTES

    scene, _ = scene
    r = scene.truth.radius
    fine = carve(scene.cameras, scene.masks, radius=r)
    core = fine.core(CarvingSettings().core_agreement).sum()
    needed = (len(fine) * _VOXEL_BYTES + core * _CORE_BYTES) / 2 ** 20
    coarse = carve(scene.cameras, scene.masks, radius=r,
                   settings=CarvingSettings(memory_mb=0.7 * needed))
    assert fine.voxel_size == pytest.approx(r / 3)
    assert coarse.voxel_size == pytest.approx(2 * fine.voxel_size)
    # the same cable: every coarse voxel's centre lies within a coarse voxel of a fine one
    from scipy.spatial import cKDTree
    distance, _ = cKDTree(fine.occupied_points()).query(coarse.occupied_points())
    assert np.percentile(distance, 95) < coarse.voxel_size
    assert 4 < len(fine) / len(coarse) < 12


def test_a_packed_mask_gives_back_the_mask_in_an_eighth_of_the_memory():
    from engine.io.packed_mask import PackedMask, unpacked

    rng = np.random.default_rng(0)
    for shape in [(7, 13), (480, 640), (1, 1)]:
        mask = rng.random(shape) < 0.3
        packed = PackedMask(mask)
        again = packed()
        assert again.dtype == bool and again.shape == shape
        np.testing.assert_array_equal(again, mask)
        assert packed.count == mask.sum() and packed.any() == mask.any()
        assert packed.nbytes == -(-mask.size // 8)
        np.testing.assert_array_equal(unpacked(packed), mask)
    assert not PackedMask(np.zeros((5, 5), bool)).any()
    assert unpacked(None) is None
    again[0, 0] = not again[0, 0]  # a caller's array is its own
    np.testing.assert_array_equal(packed(), mask)
    with pytest.raises(ValueError, match="2-D"):
        PackedMask(np.zeros((2, 2, 2), bool))


def test_a_stretch_out_of_most_frames_is_carved_from_the_views_that_frame_it():
    from engine.synthetic.cameras import out_of_frame

    scene = make_scene(SceneSpec(crossings=2, seed=4, views=16, width=640, height=480,
                                 framing=0.5))
    truth = scene.truth
    outside = out_of_frame(truth, scene.cameras)
    rarely = outside > 0.5  # seen by fewer than half the views
    assert rarely.mean() > 0.05
    grid = carve(scene.cameras, list(scene.masks))
    distance, _ = cKDTree(grid.occupied_points()).query(truth.centreline)
    held = distance <= truth.radius
    assert held[rarely].mean() > 0.9
    # a view that does not frame a voxel is no vote against it: asking every voxel to be
    # framed by half the views loses those stretches
    strict = carve(scene.cameras, list(scene.masks),
                   settings=replace(CarvingSettings(), min_view_fraction=0.5))
    distance, _ = cKDTree(strict.occupied_points()).query(truth.centreline)
    assert (distance <= truth.radius)[rarely].mean() < 0.5
