"""The result JSON (cable_recon.result/1): round trip, validation messages, safe writing."""

import json
import os

import numpy as np
import pytest

from engine import InputError, read_result, write_result
from engine.io.result import RESULT_FORMAT


def test_round_trip_keeps_everything(small_result, tmp_path):
    path = write_result(small_result, tmp_path / "r.json")
    back = read_result(path)
    assert back.radius == small_result.radius and back.units == "m"
    assert len(back.paths) == 2
    for a, b in zip(back.paths, small_result.paths):
        np.testing.assert_array_equal(a.points, b.points)
        assert a.closed == b.closed
    np.testing.assert_array_equal(back.paths[1].radii, small_result.paths[1].radii)
    assert back.paths[0].radii is None
    (crossing,) = back.crossings
    assert (crossing.over.path, crossing.over.index) == (1, 10)
    assert (crossing.under.path, crossing.under.index) == (0, 0)
    assert crossing.confidence == 0.75
    for a, b in zip(back.cameras, small_result.cameras):
        assert a.name == b.name and a.model == b.model
        np.testing.assert_array_equal(a.params, b.params)
        np.testing.assert_allclose(a.R, b.R, atol=1e-15)
        np.testing.assert_array_equal(a.t, b.t)
    assert back.warnings == small_result.warnings and back.timings == {"carve": 1.5}


def test_the_optional_colour_round_trips(small_result, tmp_path):
    from dataclasses import replace

    assert read_result(write_result(small_result, tmp_path / "a.json")).colour is None
    coloured = replace(small_result, colour=(0.8, 0.1, 0.05))
    assert read_result(write_result(coloured, tmp_path / "b.json")).colour == (0.8, 0.1, 0.05)
    with pytest.raises(ValueError, match="colour"):
        replace(small_result, colour=(2.0, 0.0, 0.0))
    # several cables: each path its own colour
    paths = (replace(small_result.paths[0], colour=(0.1, 0.2, 0.9)), small_result.paths[1])
    back = read_result(write_result(replace(small_result, paths=paths), tmp_path / "c.json"))
    assert back.paths[0].colour == (0.1, 0.2, 0.9) and back.paths[1].colour is None
    with pytest.raises(ValueError, match="colour"):
        replace(small_result.paths[0], colour=(0.5, -0.1, 0.0))


def test_file_follows_the_documented_layout(small_result, tmp_path):
    data = json.loads(write_result(small_result, tmp_path / "r.json").read_text())
    assert data["format"] == RESULT_FORMAT
    assert set(data) == {"format", "units", "radius", "paths", "crossings", "cameras",
                         "warnings", "timings"}
    camera = data["cameras"][1]
    R, t = np.array(camera["R"]), np.array(camera["t"])
    np.testing.assert_allclose(camera["center"], -R.T @ t)
    np.testing.assert_allclose(camera["K"], [[500, 0, 320], [0, 505, 240], [0, 0, 1]])
    assert camera["params"] == [500, 505, 320, 240, 0.05, -0.01, 0.001, -0.002]
    assert data["crossings"][0]["over"] == {"path": 1, "index": 10}


def test_never_overwrites_without_being_asked(small_result, tmp_path):
    target = tmp_path / "r.json"
    target.write_text("the user's file")
    with pytest.raises(FileExistsError, match="already exists"):
        write_result(small_result, target)
    assert target.read_text() == "the user's file"
    write_result(small_result, target, overwrite=True)
    assert read_result(target).radius == small_result.radius
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]  # no temporary left behind


def test_new_files_follow_the_umask(small_result, tmp_path):
    old = os.umask(0o022)
    try:
        path = write_result(small_result, tmp_path / "r.json")
    finally:
        os.umask(old)
    assert path.stat().st_mode & 0o777 == 0o644


def _valid(small_result):
    return small_result.to_dict()


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.update(format="cable_recon.result/2"), "'format' must be"),
    (lambda d: d.pop("radius"), "missing 'radius'"),
    (lambda d: d.update(radius=-1), "radius must be a positive"),
    (lambda d: d.update(units="inches"), "units must be"),
    (lambda d: d.update(paths=[]), "paths is empty"),
    (lambda d: d["paths"][0].update(points=[[0, 0, 0]]), r"paths\[0\].points needs at least 2"),
    (lambda d: d["paths"][1].update(points=[[0, 0], [1, 1]]), r"paths\[1\].points must be"),
    (lambda d: d["paths"][1].update(radii=[1.0]), r"paths\[1\].radii must hold one"),
    (lambda d: d["paths"][0].update(closed="yes"), r"paths\[0\].closed must be"),
    (lambda d: d["crossings"][0]["over"].update(index=99), r"crossings\[0\].over points at"),
    (lambda d: d["crossings"][0].update(confidence=2), r"crossings\[0\].confidence"),
    (lambda d: d["cameras"][0].update(model="FISHEYE"), r"cameras\[0\].*not supported"),
    (lambda d: d["cameras"][1].update(params=[1, 2, 3]), r"cameras\[1\].*takes 8 parameters"),
    (lambda d: d["cameras"][0].update(R=[[1, 0, 0], [0, 1, 0], [0, 0, 2]]), "not a rotation"),
    (lambda d: d.update(warnings="oops"), "warnings must be"),
    (lambda d: d.update(colour=[1.0, 0.2]), "colour must be"),
    (lambda d: d.update(colour=[1.0, 0.2, 255]), "colour must be"),
    (lambda d: d["paths"][1].update(colour=[0.5, "red", 0.1]), r"paths\[1\].colour must be"),
])
def test_malformed_files_get_a_clear_message(small_result, tmp_path, mutate, message):
    data = _valid(small_result)
    mutate(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match=message) as info:
        read_result(path)
    assert str(info.value).startswith(str(path))
    assert "\n" not in str(info.value)


def test_unreadable_files(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_result(tmp_path / "missing.json")
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(InputError, match="not valid JSON"):
        read_result(tmp_path / "broken.json")
    (tmp_path / "list.json").write_text("[]")
    with pytest.raises(InputError, match="JSON object"):
        read_result(tmp_path / "list.json")
