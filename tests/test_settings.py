"""Settings in one place: every group's fields have a range, the command line reaches all of
them with a prefix and refuses what is out of range, and a run repeats from its result."""

import dataclasses
import json

import pytest

from engine import InputError
from engine.cli.main import build_parser, main
from engine.cli.settings import PIPELINE_GROUPS, pipeline_from_arguments
from engine.io.result import read_result
from engine.pipeline import PipelineSettings, RunInputs, read_run, reconstruct, write_run
from engine.settings import bounds, out_of_range, settings_to_dict, simple_fields
from engine.stages.bezier import BezierSettings
from engine.synthetic.scene import SceneSpec, make_scene, write_scene

GROUPS = {field.name: field.default_factory for field in dataclasses.fields(PipelineSettings)
          if field.default_factory is not dataclasses.MISSING}


def every_group():
    return [*GROUPS.items(), ("curve", BezierSettings)]


def test_the_command_line_offers_every_group_of_the_pipeline():
    assert set(PIPELINE_GROUPS) == set(GROUPS)


@pytest.mark.parametrize("name, cls", every_group(), ids=lambda item: str(item))
def test_every_number_has_a_range_its_default_fits(name, cls):
    for field in simple_fields(cls):
        if field.type in (bool, "bool"):
            continue
        assert any(bound is not None for bound in bounds(field)), f"{cls.__name__}.{field.name}"
        assert out_of_range(field, field.default) is None


@pytest.mark.parametrize("name, cls", every_group(), ids=lambda item: str(item))
def test_a_value_out_of_range_is_refused_naming_its_field(name, cls):
    for field in simple_fields(cls):
        low, high, above = bounds(field)
        bad = (above - 1 if above is not None else low - 1 if low is not None
               else high + 1 if high is not None else None)
        if bad is None or field.type in (bool, "bool"):
            continue
        with pytest.raises(ValueError, match=rf"{cls.__name__}\.{field.name} must be"):
            cls(**{field.name: type(field.default)(bad)})


def _changed(field):
    """A value in range other than the default."""
    low, high, above = bounds(field)
    if field.type in (bool, "bool"):
        return not field.default
    value = field.default + 1 if (high is None or field.default + 1 <= high) else None
    if value is None:
        value = (field.default + (low if low is not None else above)) / 2
    return type(field.default)(value)


def test_every_field_of_every_group_is_a_flag_with_its_prefix():
    parser = build_parser()
    argv, expected = ["reconstruct", "frames"], {}
    for name, cls in GROUPS.items():
        values = {}
        for field in simple_fields(cls):
            value = _changed(field)
            flag = f"--{name}-{field.name}".replace("_", "-")
            if field.type in (bool, "bool"):
                argv.append(flag if value else flag.replace("--", "--no-", 1))
            else:
                argv += [flag, str(value)]
            values[field.name] = value
        expected[name] = dataclasses.replace(cls(), **values)
    settings = pipeline_from_arguments(parser.parse_args(argv))
    for name, value in expected.items():
        assert getattr(settings, name) == value, name


@pytest.mark.parametrize("argv, message", [
    (["--carving-vote", "1.5"], "--carving-vote must be > 0 and <= 1, not 1.5"),
    (["--vote", "0"], "--carving-vote must be > 0 and <= 1, not 0.0"),
    (["--topology-max-degree", "2.5"], "--topology-max-degree must be a whole number"),
    (["--fit-passes", "0"], "--fit-passes must be >= 1, not 0"),
])
def test_flags_out_of_range_are_bad_input(capsys, argv, message):
    with pytest.raises(SystemExit) as stop:
        main(["reconstruct", "frames", *argv])
    assert stop.value.code == 2 and message in capsys.readouterr().err


def test_flags_that_do_not_fit_together_are_bad_input(capsys):
    assert main(["reconstruct", "frames", "--agreement-keep-distance", "2"]) == 2
    assert "remove_distance must be at least keep_distance" in capsys.readouterr().err


def test_flags_of_earlier_versions_still_work():
    args = build_parser().parse_args(["reconstruct", "frames", "--all-cables", "--memory-mb",
                                      "512", "--edge-reach", "3", "--reference-frame", "4"])
    settings = pipeline_from_arguments(args)
    assert settings.segmentation.all_cables and settings.carving.memory_mb == 512
    assert settings.segmentation.edge_reach == 3 and settings.reference_frame == 4
    # one name, two groups: each keeps its own
    args = build_parser().parse_args(["reconstruct", "frames", "--graph-spur-length", "1.5"])
    settings = pipeline_from_arguments(args)
    assert settings.graph.spur_length == 1.5
    assert settings.topology.spur_length == PipelineSettings().topology.spur_length


def test_a_run_file_reads_back_and_flags_change_it(tmp_path):
    settings = dataclasses.replace(
        PipelineSettings(reference_frame=2),
        carving=dataclasses.replace(PipelineSettings().carving, voxels_per_radius=2.5),
        topology=dataclasses.replace(PipelineSettings().topology, confident=0.8))
    path = write_run(tmp_path / "run.json", settings, RunInputs(hsv="0,90,60,10,255,255",
                                                                  diameter=6.0))
    assert read_run(path) == (settings, RunInputs("0,90,60,10,255,255", 6.0, None))
    with pytest.raises(FileExistsError):
        write_run(path, settings, RunInputs())
    args = build_parser().parse_args(["reconstruct", "frames", "--settings", str(path),
                                      "--topology-confident", "0.95"])
    read, _ = read_run(path)
    changed = pipeline_from_arguments(args, read)
    assert changed.carving.voxels_per_radius == 2.5 and changed.reference_frame == 2
    assert changed.topology.confident == 0.95


@pytest.mark.parametrize("document, message", [
    ({"format": "cable_recon.result/1"}, "records no run"),
    ({"run": {"settings": {"carving": {"voxel_size": 1}}}}, "voxel_size is not a setting"),
    ({"run": {"settings": {"carving": {"vote": 3}}}}, "CarvingSettings.vote must be"),
    ({"run": {"settings": {}, "inputs": {"diameter": "thick"}}}, "diameter must be a number"),
    ({"run": {"settings": {}, "inputs": {"hsv": "red"}}}, "--hsv 'red'"),
])
def test_a_bad_run_file_is_a_clear_input_error(tmp_path, document, message):
    path = tmp_path / "run.json"
    path.write_text(json.dumps(document))
    with pytest.raises(InputError, match=message):
        read_run(path)


def test_a_run_repeats_exactly_from_its_result_file(tmp_path):
    capture = write_scene(make_scene(SceneSpec(crossings=1, seed=4, views=12, width=480,
                                               height=360)), tmp_path / "loop")
    settings = dataclasses.replace(
        PipelineSettings(),
        carving=dataclasses.replace(PipelineSettings().carving, voxels_per_radius=2.5),
        fit=dataclasses.replace(PipelineSettings().fit, passes=1))
    first = reconstruct(capture / "images", cameras=capture / "sparse", settings=settings,
                        diameter=4.0)
    assert first.run == {"settings": settings_to_dict(settings),
                         "inputs": {"hsv": None, "diameter": 4.0, "length": None}}
    from engine.io.result import write_result

    write_result(first, tmp_path / "first.json")
    assert read_result(tmp_path / "first.json").run == first.run
    assert main(["-q", "reconstruct", str(capture / "images"), "--cameras",
                 str(capture / "sparse"), "--settings", str(tmp_path / "first.json"),
                 "-o", str(tmp_path / "again.json")]) == 0
    again = read_result(tmp_path / "again.json")
    assert again.run == first.run and again.units == "m"
    for a, b in zip(first.paths, again.paths):
        assert (a.points == b.points).all()
