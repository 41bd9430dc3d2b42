"""From masks to the segment graph on ground-truth scenes (§3.2–3.3 together)."""

import pytest

from engine.bench.carve import graph_scores
from engine.stages.carving import CarvingSettings, carve
from engine.stages.segment_graph import extract_segment_graph_from_voxels
from engine.stages.segmentation import cable_width, junction_map
from engine.synthetic.scene import SceneSpec, make_scene


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


def test_bench_carve_carves_as_a_user_and_labels_the_truth_fed_grid(tmp_path):
    from engine.bench.carve import _scene_rows

    spec = SceneSpec(crossings=2, seed=3, views=12, width=640, height=480)
    ours, oracle = _scene_rows([("table 2", spec)], CarvingSettings(), tmp_path, 128)
    assert ours["grid_from"] == "ours" and oracle["grid_from"].startswith("oracle: true radius")
    # ours sizes its voxels from the radius it estimated: the settings' voxels per radius
    assert ours["voxels_across"] == pytest.approx(2 * CarvingSettings().voxels_per_radius)
    assert oracle["voxels_across"] != pytest.approx(ours["voxels_across"])
    assert ours["crossings_found"] == ours["crossings"] == 2
    assert [row["grid_from"] for row in _scene_rows([("t", spec)], CarvingSettings(),
                                                    tmp_path, 0)] == ["ours"]
