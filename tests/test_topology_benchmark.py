"""``bench topology``: its families, its summary of the scenes' rows, its command line."""

import inspect

import pytest

from engine.bench.topology import (CAPTURE_FAMILY, SCENE_COLUMNS, SUMMARY_COLUMNS,
                                   TOPOLOGY_FAMILIES, _summary, bench_topology,
                                   topology_spec)
from engine.synthetic.scene import HARD_FRAMING, SceneSpec, make_scene, write_scene


def test_the_families_are_the_easy_layouts_and_the_partly_framed_heaps():
    easy = [topology_spec("easy", seed) for seed in range(6)]
    assert {spec.kind for spec in easy} == {"table"}
    assert sorted(spec.crossings for spec in easy) == [3, 4, 5, 6, 7, 8]
    assert all(spec.framing == 1.0 for spec in easy)
    hard = topology_spec("hard", 1000, views=20)
    assert (hard.kind, hard.seed, hard.views, hard.framing) == ("hard", 1000, 20, HARD_FRAMING)
    assert (hard.width, hard.height) == (960, 720)
    with pytest.raises(ValueError, match="unknown topology family 'tangle'"):
        topology_spec("tangle", 0)


def _row(checks, one_path="yes", mean=0.1, p95=0.3, topology=0.5):
    return {"checks": checks, "one_path": one_path, "accuracy_mean": mean,
            "accuracy_p95": p95, "completeness": 1.0, "topology_s": topology, "total_s": 9.0}


def test_a_summary_counts_scenes_crossings_and_doubt():
    rows = [_row([(True, 0.95), (True, 0.99)]),
            _row([(True, 0.95), (False, 0.5)], mean=0.2, p95=0.9, topology=1.5),  # doubted
            _row([(True, None), (False, 0.97)], one_path="no"),                   # confident
            {"error": "no path could be formed", "total_s": 3.0}]
    summary = _summary("hard", "tuning", "ours", rows)
    assert set(summary) <= set(SUMMARY_COLUMNS)
    assert summary["scenes"] == 4 and summary["errors"] == 1
    assert summary["all_right"] == "1/4"
    assert summary["crossings"] == "4/6"
    assert summary["confident_right"] == "3/4"
    assert summary["wrong_undoubted"] == 1
    assert summary["accuracy_worst"] == 0.2 and summary["p95_worst"] == 0.9
    assert summary["accuracy_mean"] == pytest.approx(0.4 / 3)
    assert summary["topology_s_max"] == 1.5
    failed = _summary("hard", "held-out", "ours", [{"error": "x"}])
    assert failed["errors"] == 1 and "all_right" not in failed


def test_the_command_line_gives_the_bench_its_families(monkeypatch, capsys):
    import engine.bench.topology
    from engine.cli.main import main

    signature = inspect.signature(engine.bench.topology.bench_topology)
    calls = []

    def fake(*args, **kwargs):
        signature.bind(*args, **kwargs)
        calls.append(kwargs)
        return ([{"family": "hard", "set": "tuning", "masks": "ours", "scenes": 1}],
                [{"family": "hard", "seed": 0, "error": "scene: no layout"}])

    monkeypatch.setattr(engine.bench.topology, "bench_topology", fake)
    assert main(["-q", "bench", "topology", "--families", "hard", "--seeds", "2"]) == 0
    assert calls[-1]["families"] == ("hard",) and calls[-1]["seeds"] == 2
    assert calls[-1]["captures"] is None  # chosen families only
    out = capsys.readouterr().out
    assert out.count("| family |") == 2 and "scene: no layout" in out
    assert all(column in out for column in SCENE_COLUMNS)
    assert main(["-q", "bench", "topology"]) == 0
    assert "families" not in calls[-1] and "captures" not in calls[-1]  # all, captures too
    capsys.readouterr()
    assert main(["-q", "bench", "topology", "--families", "easy,knots"]) == 2
    assert "unknown topology family knots" in capsys.readouterr().err
    assert TOPOLOGY_FAMILIES == ("easy", "hard")


def test_captures_are_a_held_out_family_of_their_own(tmp_path):
    captures = tmp_path / "hard"
    write_scene(make_scene(SceneSpec(crossings=1, seed=2, views=8, width=480, height=360)),
                captures / "hard-7")
    (captures / "notes").mkdir()  # a folder without a ground truth is no capture
    summary, scenes = bench_topology(seeds=0, families=(), captures=captures)
    assert [(row["family"], row["set"], row["seed"]) for row in scenes] == \
        [(CAPTURE_FAMILY, "held-out", "hard-7")] * 2
    assert {row["masks"] for row in scenes} == {"oracle: exact", "ours"}
    assert all(row["true_crossings"] == 1 and "error" not in row for row in scenes)
    assert [(row["family"], row["masks"], row["scenes"]) for row in summary] == \
        [(CAPTURE_FAMILY, "oracle: exact", 1), (CAPTURE_FAMILY, "ours", 1)]
    assert summary[0]["crossings"] == "1/1"  # a real, scored run
    assert bench_topology(seeds=0, families=(), captures=tmp_path / "none") == ([], [])
