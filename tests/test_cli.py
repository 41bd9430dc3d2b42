"""`python -m engine` as a pipeline runs it: version, help, exit codes."""

import inspect
import subprocess
import sys

import pytest

from conftest import ROOT
from engine import __version__


def run_engine(*args):
    return subprocess.run([sys.executable, "-m", "engine", *args], cwd=ROOT,
                          capture_output=True, text=True)


def test_version():
    run = run_engine("--version")
    assert run.returncode == 0 and run.stdout.strip() == f"cable_recon {__version__}"


def test_no_command_is_a_usage_error():
    run = run_engine()
    assert run.returncode == 2 and "usage:" in run.stderr


def test_unknown_command_is_a_usage_error():
    run = run_engine("frobnicate")
    assert run.returncode == 2 and "invalid choice" in run.stderr


def test_a_bug_is_one_line_naming_where_with_the_traceback_in_a_file():
    import io
    import re
    from pathlib import Path

    import numpy as np
    import pytest

    from engine.cli.main import EXIT_BUG, run_with_exit_code
    from engine.stages.carving import carve

    not_a_camera = object()
    stream = io.StringIO()
    code = run_with_exit_code(carve, [not_a_camera], [np.zeros((2, 2), bool)], stream=stream)
    line = stream.getvalue()
    assert code == EXIT_BUG == 4 and line.count("\n") == 1
    # the deepest frame of the engine: module, function, line
    assert re.match(r"internal error \(a bug, please report it\) in "
                    r"engine\.geometry\.camera\.\S+:\d+: AttributeError: ", line)
    traceback_file = Path(re.search(r"the traceback is in (\S+)\)", line).group(1))
    assert "Traceback" in traceback_file.read_text()
    traceback_file.unlink()
    with pytest.raises(AttributeError):  # --debug: the traceback itself
        run_with_exit_code(carve, [not_a_camera], [np.zeros((2, 2), bool)], stream=stream,
                           debug=True)


def test_an_output_that_cannot_be_written_is_named_before_the_work(tmp_path):
    images = tmp_path / "images"
    images.mkdir()  # (empty: the output is checked first, whatever the input)
    for command in (["reconstruct", str(images), "-o", "/sys/result.json"],
                    ["segment", str(images), "-o", "/sys/masks", "--no-agreement"],
                    ["cameras", str(images), "-o", "/sys/model"]):
        run = run_engine(*command)
        assert run.returncode == 2, run.stderr
        assert run.stderr.strip() == "error: cannot write in /sys: Permission denied"
    (tmp_path / "taken").mkdir()
    run = run_engine("reconstruct", str(images), "-o", str(tmp_path / "taken"), "--overwrite")
    assert run.returncode == 2
    assert run.stderr.strip() == f"error: {tmp_path / 'taken'} is a folder, not a file"


def test_a_full_disk_leaves_nothing_behind(tmp_path, monkeypatch):
    import errno
    import os

    import numpy as np
    import pytest

    from engine.errors import OutputError
    from engine.io.files import write_atomic, write_image

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    (tmp_path / "kept.json").write_text("the user's")
    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OutputError, match=r"cannot write .*r\.json: No space left on device"):
        write_atomic(tmp_path / "r.json", "{}")
    with pytest.raises(OutputError, match="No space left"):
        write_atomic(tmp_path / "kept.json", "{}", overwrite=True)
    with pytest.raises(OutputError, match="No space left"):
        write_image(tmp_path / "m.png", np.zeros((4, 4), np.uint8))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.json"]  # no temporary left
    assert (tmp_path / "kept.json").read_text() == "the user's"


def test_bench_families_are_checked_before_the_work():
    done = run_engine("bench", "looks", "--families", "saturated,tartan")
    assert done.returncode == 2
    assert "unknown look family tartan" in done.stderr and "two_cables" in done.stderr


@pytest.mark.parametrize("stage", ["looks", "pipeline-looks"])
def test_bench_families_reach_the_bench(monkeypatch, capsys, stage):
    import engine.bench.looks
    import engine.bench.pipeline
    from engine.cli.main import main

    calls = []
    for module, name in ((engine.bench.looks, "bench_looks"),
                         (engine.bench.pipeline, "bench_pipeline_looks")):
        signature = inspect.signature(getattr(module, name))

        def fake(*args, _signature=signature, **kwargs):
            _signature.bind(*args, **kwargs)  # the bench takes what the command line gives
            calls.append(kwargs)
            return [{"looks": "x"}]

        monkeypatch.setattr(module, name, fake)
    assert main(["-q", "bench", stage, "--families", "two_cables,pale"]) == 0
    assert calls[-1]["families"] == ("two_cables", "pale") and calls[-1]["captures"] is None


@pytest.mark.parametrize("stage", ["looks", "pipeline-looks"])
def test_bench_takes_the_masks_settings_as_reconstruct_does(monkeypatch, stage):
    import engine.bench.looks
    import engine.bench.pipeline
    from engine.cli.main import main

    calls = []
    for module, name in ((engine.bench.looks, "bench_looks"),
                         (engine.bench.pipeline, "bench_pipeline_looks")):
        monkeypatch.setattr(module, name, lambda **kwargs: calls.append(kwargs) or [{}])
    assert main(["-q", "bench", stage, "--segmentation-side-reach", "0", "--ours-only"]) == 0
    given = calls[-1]["settings" if stage == "looks" else "segmentation"]
    assert given.side_reach == 0.0 and given.shadow_chroma == 0.02
    if stage == "pipeline-looks":
        assert calls[-1]["masks"] == ("ours",)
        assert main(["-q", "bench", stage]) == 0  # the defaults: the bench's own per family
        assert calls[-1]["segmentation"] is None and len(calls[-1]["masks"]) == 3
