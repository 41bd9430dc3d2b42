"""Many sequences: ``python -m engine batch`` and the add-on's ``batch`` command."""

import json
import re
import shutil
import signal
import subprocess
import sys
import threading

import bpy
import cv2
import numpy as np
import pytest

from conftest import ROOT
from engine import Cancelled, InputError, read_result
from engine.batch import SUMMARY, find_sequences, run_batch
from engine.pipeline import PipelineSettings, RunInputs, reconstruct
from engine.synthetic.scene import SceneSpec, make_scene, write_scene
from engine.threads import MOST_THREADS, cpu_count


@pytest.fixture(scope="module")
def sequences(tmp_path_factory):
    """Two small captures (images/, sparse/ inside each) and one of a grey table alone."""
    folder = tmp_path_factory.mktemp("batch") / "shots"
    for name, seed in (("alpha", 3), ("beta", 5)):
        write_scene(make_scene(SceneSpec(crossings=2, seed=seed, views=10, width=480,
                                         height=360, radius=0.006, image_format="jpg")),
                    folder / name)
    grey = folder / "grey"
    (grey / "images").mkdir(parents=True)
    for k in range(6):
        cv2.imwrite(str(grey / "images" / f"{k:03d}.png"), np.full((360, 480, 3), 128, np.uint8))
    shutil.copytree(folder / "alpha" / "sparse", grey / "sparse")
    return folder


def run_engine(*args):
    return subprocess.run([sys.executable, "-m", "engine", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


def rows(output):
    return {row["name"]: row for row in json.loads((output / SUMMARY).read_text())["sequences"]}


def test_sequences_are_folders_of_frames_or_images_folders_or_videos(tmp_path):
    for name in ("b10", "b9", "a/images", ".hidden", "empty"):
        (tmp_path / name).mkdir(parents=True)
    for name in ("b10/0.png", "b9/0.jpg", "a/images/0.JPG", ".hidden/0.png", "notes.txt",
                 "c.mp4"):
        (tmp_path / name).write_bytes(b"")
    found = find_sequences(tmp_path)
    assert [(s.name, s.images.relative_to(tmp_path).as_posix()) for s in found] == [
        ("a", "a/images"), ("b9", "b9"), ("b10", "b10"), ("c", "c.mp4")]
    assert found[0].folder == tmp_path / "a" and found[3].folder == tmp_path / "c"
    (tmp_path / "a.mov").write_bytes(b"")
    with pytest.raises(InputError, match="would both be sequence 'a'"):
        find_sequences(tmp_path)
    with pytest.raises(InputError, match="holds no sequence"):
        find_sequences(tmp_path / "empty")
    with pytest.raises(InputError, match="does not exist"):
        find_sequences(tmp_path / "nowhere")


def test_each_sequence_gets_its_result_and_a_failure_stops_no_other(sequences, tmp_path):
    output = tmp_path / "out"
    run = run_engine("batch", sequences, "-o", output, "--cameras", "sparse", "--jobs", "2")
    assert run.returncode == 3, run.stderr  # the grey one: no cable
    summary = rows(output)
    assert [summary[n]["status"] for n in ("alpha", "beta", "grey")] == ["done", "done",
                                                                           "failed"]
    assert summary["grey"]["reason"].startswith("reconstruction failed: no cable pixels")
    assert "no cable pixels" in (output / "grey.log").read_text()
    assert not (output / "grey.cable.json").exists()
    assert summary["alpha"]["paths"] == 1 and summary["alpha"]["crossings"] == 2
    assert re.search(r"^sequence +status +seconds", run.stderr, re.M)  # the table
    # each as `reconstruct` makes it alone
    alone = reconstruct(sequences / "alpha" / "images", cameras=sequences / "alpha" / "sparse")
    batch = read_result(output / "alpha.cable.json")
    assert np.array_equal(batch.paths[0].points, alone.paths[0].points)
    # two runs side by side share the cores out
    assert batch.run["settings"]["workers"] == max(min(cpu_count() // 2, MOST_THREADS), 1)

    # again (one run at a time, so with other workers): the finished ones are skipped, the
    # failed one is tried again
    made = {n: (output / f"{n}.cable.json").read_bytes() for n in ("alpha", "beta")}
    again = run_engine("-q", "batch", sequences, "-o", output, "--cameras", "sparse",
                       "--jobs", "1")
    assert again.returncode == 3  # -q: the failure alone is said
    assert again.stderr.strip().splitlines() == [
        f"grey: {summary['grey']['reason']}"]
    summary = rows(output)
    assert [summary[n]["status"] for n in ("alpha", "beta", "grey")] == ["skipped", "skipped",
                                                                           "failed"]
    assert summary["alpha"]["crossings"] == 2
    # other settings, or other inputs: the results made before are left alone, and said so
    for options, code in ((["--diameter", "8"], 3), (["--masks", "masks"], 2)):
        other = run_engine("-q", "batch", sequences, "-o", output, "--cameras", "sparse",
                           *options)
        assert other.returncode == code  # with masks, the grey one has none: bad input
        assert "other settings or inputs" in rows(output)["alpha"]["reason"]
        assert {n: (output / f"{n}.cable.json").read_bytes() for n in made} == made
    # until asked to replace them
    replaced = run_engine("-q", "batch", sequences, "-o", output, "--cameras", "sparse",
                          "--diameter", "8", "--overwrite", "--obj")
    assert replaced.returncode == 3
    assert rows(output)["alpha"]["status"] == "done"
    assert read_result(output / "alpha.cable.json").units == "m"
    assert (output / "alpha.obj").stat().st_size > 0


def test_bad_batch_input_is_one_line(sequences, tmp_path):
    for args, message in ((["batch", tmp_path / "nowhere"], "does not exist"),
                          (["batch", sequences / "alpha" / "images"], "it is one sequence"),
                          (["batch", sequences / "alpha" / "sparse"], "holds no sequence"),
                          (["batch", sequences, "--jobs", "0"], "--jobs must be 1 or more")):
        run = run_engine(*args)
        assert run.returncode == 2 and message in run.stderr, run.stderr
        assert len(run.stderr.strip().splitlines()) == 1
    (tmp_path / "file").write_text("")
    run = run_engine("batch", sequences, "-o", tmp_path / "file")
    assert run.returncode == 2 and "is a file, not a folder" in run.stderr
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "summary.json").write_text("{}")  # someone else's
    run = run_engine("batch", sequences, "-o", tmp_path / "mine")
    assert run.returncode == 2 and "is not a batch's summary" in run.stderr
    assert (tmp_path / "mine" / "summary.json").read_text() == "{}"


@pytest.mark.parametrize("sigint", ["handled", "ignored"])
def test_a_cancelled_batch_stops_its_runs_and_leaves_no_result(sequences, tmp_path, sigint):
    # "ignored": the batch was started in the background by a shell script, so it and the
    # runs it starts inherit an ignored SIGINT; the cancel must stop them all the same
    before = signal.signal(signal.SIGINT, signal.SIG_IGN if sigint == "ignored"
                           else signal.default_int_handler)
    try:
        _cancel_a_batch(sequences, tmp_path)
    finally:
        signal.signal(signal.SIGINT, before)


def _cancel_a_batch(sequences, tmp_path):
    cancel = threading.Event()
    started = set()

    def progress(fraction, message):
        # "0/3 done; alpha 4% masks: 000.jpg; beta 0%": a run that names its stage is under way
        for part in message.split("; ")[1:]:
            name, _, stage = part.partition(" ")
            if stage.partition("% ")[2]:
                started.add(name)
        if started >= {"alpha", "beta"}:  # both runs are under way
            cancel.set()

    output = tmp_path / "out"
    found = find_sequences(sequences)
    with pytest.raises(Cancelled):
        run_batch(found, output, PipelineSettings(), RunInputs(), cameras="sparse", jobs=2,
                  progress=progress, cancel=cancel)
    assert not list(output.glob("*.cable.json"))
    summary = rows(output)
    assert {row["status"] for row in summary.values()} == {"cancelled"}
    assert summary["grey"]["reason"] == "not started"
    # the two runs were stopped as Ctrl-C stops one: each said so and cleaned up
    for name in ("alpha", "beta"):
        assert summary[name]["reason"] == "cancelled"
        assert (output / f"{name}.log").read_text().strip().endswith("cancelled")
    assert not list(output.glob("*.tmp"))


def test_blender_batch_writes_a_blend_per_sequence(addon, sequences, tmp_path, capsys):
    from cable_reconstruction.addon.batch_command import handle_command

    output = tmp_path / "blends"
    code = handle_command(["batch", str(sequences), "-o", str(output), "--cameras", "sparse",
                           "--no-cameras", "-q"])
    assert code == 3, capsys.readouterr().err
    assert "2 .blend file(s) written" in capsys.readouterr().err
    assert sorted(p.name for p in output.glob("*.blend")) == ["alpha.blend", "beta.blend"]
    bpy.ops.wm.open_mainfile(filepath=str(output / "beta.blend"))
    obj = bpy.data.objects["beta"]
    assert obj.type == "CURVE" and obj.data.splines[0].type == "BEZIER"
    assert "beta cameras" not in bpy.data.collections  # the startup file's camera only
    stored = json.loads(obj.cable_recon.arguments)
    assert stored["cameras"] == str((sequences / "beta" / "sparse").resolve())
    before = (output / "beta.blend").read_bytes()
    assert handle_command(["batch", str(sequences), "-o", str(output), "--cameras", "sparse",
                           "-q"]) == 3
    assert "kept (--overwrite replaces them): alpha.blend, beta.blend" in \
        capsys.readouterr().err
    assert (output / "beta.blend").read_bytes() == before
    bpy.ops.wm.read_homefile(use_empty=True)


def test_a_runs_lines_are_read_whole_however_its_log_is_cut():
    from engine.batch import _Child

    chunks = iter(["[###...] 10% mas", "ks\nwarning: a frame\nreconstruction fai",
                   "led: no path", ""])
    reader = type("Reader", (), {"read": lambda self: next(chunks)})()
    child = _Child(sequence=None, process=None, log_path=None, reader=reader, started=0.0)
    child.read()
    assert child.lines == [] and child.fraction == 0.0  # half a progress line: not yet
    child.read()
    assert child.fraction == 0.1 and child.stage == "masks"
    assert child.lines == ["warning: a frame"]
    child.read(ended=True)  # the run ended: its last line counts without a newline
    assert child.lines[-1] == "reconstruction failed: no path"
