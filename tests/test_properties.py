"""Property-based tests of what reads a user's files and arguments: the result JSON reader,
the COLMAP model reader and the command line. Whatever the input, the answer is a result or
an ``InputError`` (the command line: a documented exit code), never another exception."""

import copy
import json

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from engine import InputError
from engine.cli.main import main
from engine.geometry.camera import Camera
from engine.io.colmap import read_colmap_model, write_colmap_model
from engine.io.result import CablePath, Crossing, Result, StrandRef, read_result, result_from_dict

#: Any JSON value.
JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-10**6, 10**6)
    | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=8),
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=12)

SLOW = settings(max_examples=150, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])


def _camera(name="frame0.png"):
    return Camera(name=name, width=64, height=48, model="PINHOLE",
                  params=np.array([60.0, 60.0, 32.0, 24.0]), R=np.eye(3),
                  t=np.array([0.0, 0.0, 1.0]))


def _valid_document():
    points = np.column_stack([np.linspace(0, 1, 6), np.zeros(6), np.zeros(6)])
    result = Result(radius=0.01, paths=(CablePath(points),),
                    crossings=(Crossing(np.zeros(3), StrandRef(0, 1), StrandRef(0, 4), 0.8),),
                    cameras=(_camera(),), units="m", warnings=("w",), timings={"fit": 1.0},
                    colour=[0.5, 0.2, 0.1])
    return result.to_dict()


def _paths(document, prefix=()):
    """Every key path into a JSON document."""
    yield prefix
    if isinstance(document, dict):
        for key, value in document.items():
            yield from _paths(value, prefix + (key,))
    elif isinstance(document, list):
        for index, value in enumerate(document):
            yield from _paths(value, prefix + (index,))


VALID = _valid_document()
PATHS = [path for path in _paths(VALID) if path]


def _replaced(document, path, value):
    document = copy.deepcopy(document)
    place = document
    for key in path[:-1]:
        place = place[key]
    place[path[-1]] = value
    return document


def test_the_valid_document_reads():
    assert isinstance(result_from_dict(copy.deepcopy(VALID)), Result)


@pytest.mark.parametrize("path", PATHS, ids=lambda path: ".".join(map(str, path)))
@settings(max_examples=30, deadline=None)
@given(value=JSON)
def test_any_field_of_a_result_replaced_reads_or_is_an_input_error(path, value):
    try:
        assert isinstance(result_from_dict(_replaced(VALID, path, value)), Result)
    except InputError as error:
        assert "\n" not in str(error)


@SLOW
@given(JSON)
def test_any_json_document_reads_or_is_an_input_error(value):
    try:
        result_from_dict(value)
    except InputError:
        pass


@SLOW
@given(st.lists(st.tuples(st.integers(0, 10**6), st.binary(max_size=3)), min_size=1,
                max_size=4))
def test_any_damaged_file_reads_or_is_an_input_error(tmp_path, edits):
    """A valid file with a few bytes replaced (cut short, garbled, not UTF-8, not JSON)."""
    data = bytearray(json.dumps(VALID).encode())
    for position, replacement in edits:
        position %= len(data) + 1
        data[position:position + len(replacement) + 1] = replacement
    path = tmp_path / "result.json"
    path.write_bytes(bytes(data))
    try:
        read_result(path)
    except InputError:
        pass


def _model_lines(tmp_path):
    folder = tmp_path / "model"
    write_colmap_model(folder, [_camera("a.png"), _camera("b.png")], overwrite=True)
    return folder, {name: (folder / name).read_text().splitlines()
                    for name in ("cameras.txt", "images.txt")}


TOKENS = st.sampled_from(["1", "0", "-1", "2", "1e9", "nan", "inf", "PINHOLE", "FISHEYE",
                          "SIMPLE_RADIAL", "a.png", "", "#", "x", "0.5", "999999999999"])


@SLOW
@given(file=st.sampled_from(["cameras.txt", "images.txt"]), line=st.integers(0, 8),
       tokens=st.lists(TOKENS, max_size=12))
# found by this test: pycolmap's reader raised IndexError ("unordered_map::at")
@example(file="images.txt", line=0, tokens=["0.5", "1", "1", "1", "1", "1", "1", "1"])
def test_any_line_of_a_colmap_model_replaced_reads_or_is_an_input_error(tmp_path, file, line,
                                                                        tokens):
    folder, files = _model_lines(tmp_path)
    lines = list(files[file])
    lines[min(line, len(lines) - 1)] = " ".join(tokens)
    (folder / file).write_text("\n".join(lines) + "\n")
    try:
        model = read_colmap_model(folder)
        assert model.cameras
    except InputError as error:
        assert "\n" not in str(error)


ARGUMENTS = st.sampled_from([
    "reconstruct", "segment", "--hsv", "1,2,3,4,5,6", "1,2,3", "-1,0,0,0,0,0", "--auto",
    "--cameras", "--masks", "--diameter", "--length", "0", "-3", "nan", "1e400", "-o",
    "--overwrite", "--reference-frame", "99", "--memory-mb", "--vote", "2", "0.5", "-q",
    "--no-agreement", "/nonexistent/folder", "x.json", "--obj", "--edge-reach",
    "--voxels-per-radius"])


@SLOW
@given(st.lists(ARGUMENTS, max_size=8))
def test_any_command_line_is_a_documented_exit_code(arguments):
    """Arguments that name no real folder: every run ends at parsing or input checking."""
    try:
        code = main(["-q", *arguments])
    except SystemExit as exit_:  # argparse: usage errors, --help
        code = exit_.code
    assert code in (0, 2, 3)


def test_the_command_line_property_is_not_vacuous(tmp_path):
    with pytest.raises(SystemExit) as exit_:
        main(["reconstruct", "--vote", "x"])
    assert exit_.value.code == 2
    assert main(["-q", "reconstruct", str(tmp_path / "missing")]) == 2
    document = tmp_path / "r.json"
    document.write_text(json.dumps(VALID))
    assert isinstance(read_result(document), Result)
