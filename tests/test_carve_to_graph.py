"""From masks to the segment graph on ground-truth scenes (§3.2–3.3 together)."""

import pytest

from engine.carving import CarvingSettings, carve
from engine.carving_benchmark import graph_scores
from engine.segment_graph import extract_segment_graph_from_voxels
from engine.segmentation import cable_width, junction_map
from engine.synthetic_scene import SceneSpec, make_scene


def _graph(spec):
    scene = make_scene(spec)
    junctions = [junction_map(mask, cable_width(mask)) for mask in scene.masks]
    grid = carve(scene.cameras, scene.masks, junctions)
    core = grid.core(CarvingSettings().core_agreement)
    graph = extract_segment_graph_from_voxels(grid.index[core], grid.junction[core],
                                              origin=grid.origin, voxel_size=grid.voxel_size,
                                              radius=grid.radius)
    return graph_scores(graph, scene.truth)


@pytest.mark.parametrize("spec", [
    SceneSpec(crossings=3, seed=1, views=24, width=800, height=600),
    SceneSpec(kind="loop", crossings=2, seed=6, views=24, width=800, height=600),
], ids=["open cable, 3 crossings", "closed loop, 2 crossings"])
def test_every_crossing_is_one_junction_of_four_branches(spec):
    scores = _graph(spec)
    assert scores["crossings_found"] == scores["crossings"]
    assert scores["junctions"] == scores["crossings"]
    assert scores["segments"] == scores["segments_expected"]
    assert scores["chain_mean_r"] < 0.5  # before any rod fitting
