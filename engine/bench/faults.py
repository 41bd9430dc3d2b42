"""The fault table: bad input a user can give ``python -m engine reconstruct``, and what the
command does with it (``python -m engine bench faults``).

Each fault is built from one small synthetic capture (10 views at 480x360 of a 2-crossing
cable, true cameras in ``sparse/``) and run as a user runs it, in a subprocess: the exit code,
the first line on stderr, whether a traceback or an internal error (exit 4) showed, and
whether anything was written or changed that should not have been. Some faults are in the
run rather than its input: an output one may not write, a full disk (a file size limit), and
Ctrl-C pressed in each stage (exit 130, nothing written).
"""

import dataclasses
import os
import re
import resource
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

__all__ = ["FAULTS", "bench_faults", "with_exif_orientation"]


def _capture(folder):
    """The clean capture every fault starts from."""
    from ..synthetic.scene import SceneSpec, make_scene, write_scene

    write_scene(make_scene(SceneSpec(crossings=2, seed=3, views=10, width=480, height=360,
                                     radius=0.006, image_format="jpg")), folder)
    return folder


def _frames(folder):
    return sorted((folder / "images").iterdir())


def _replace_frames(folder, make):
    """Every frame replaced by ``make(image)`` (same name)."""
    for path in _frames(folder):
        image = cv2.imread(str(path))
        cv2.imwrite(str(path), make(image))


def _keep_frames(folder, count):
    for path in _frames(folder)[count:]:
        path.unlink()


def _to_png(folder, convert):
    """Frames as PNGs converted by ``convert(bgr image)``, the model renamed with them."""
    for path in _frames(folder):
        image = cv2.imread(str(path))
        cv2.imwrite(str(path.with_suffix(".png")), convert(image))
        path.unlink()
    _text_model(folder)
    _model_text(folder, lambda text: text.replace(".jpg", ".png"))


def with_exif_orientation(data, orientation=6):
    """JPEG bytes with an EXIF orientation tag (6: the phone was turned, show it rotated a
    quarter turn clockwise), as a phone writes a portrait photo."""
    tiff = (b"II*\x00" + struct.pack("<I", 8) + struct.pack("<H", 1)
            + struct.pack("<HHII", 0x0112, 3, 1, orientation) + struct.pack("<I", 0))
    app1 = b"\xff\xe1" + struct.pack(">H", 2 + 6 + len(tiff)) + b"Exif\x00\x00" + tiff
    return data[:2] + app1 + data[2:]


def _rotated_by_exif(folder):
    for path in _frames(folder):
        path.write_bytes(with_exif_orientation(path.read_bytes()))


def _to_cmyk(folder):
    """Every frame re-saved as a CMYK JPEG (as print workflows and some scanners write them)."""
    from PIL import Image

    for path in _frames(folder):
        with Image.open(path) as image:
            image.convert("CMYK").save(path, quality=95)


def _recropped(folder, width, height, scale):
    """Every frame scaled by ``scale`` and cropped about its centre to ``width`` x ``height``,
    the model's cameras with it (a larger ``width`` makes huge frames, a smaller crop cuts
    the cable off at the frame's edges in every view)."""
    from ..io.colmap import read_colmap_model, write_colmap_model

    model = read_colmap_model(folder / "sparse")
    cameras = []
    for camera in model.cameras:
        left = (camera.width * scale - width) / 2
        top = (camera.height * scale - height) / 2
        fx, fy, cx, cy = camera.params
        cameras.append(dataclasses.replace(camera, width=width, height=height, params=np.array(
            [fx * scale, fy * scale, cx * scale - left, cy * scale - top])))
        path = folder / "images" / camera.name
        if path.is_file():  # (the model may name more frames than are kept)
            image = cv2.imread(str(path))
            image = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC)
            cv2.imwrite(str(path), image[int(top):int(top) + height, int(left):int(left) + width])
    shutil.rmtree(folder / "sparse")
    write_colmap_model(folder / "sparse", cameras)


def _truncate(path):
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])


def _corrupt(path):
    data = bytearray(path.read_bytes())
    rng = np.random.default_rng(0)
    middle = len(data) // 2
    data[middle:middle + 400] = rng.integers(0, 256, 400, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))


def _mask_folder(folder, size=None, drop=0):
    masks = folder / "given_masks"
    shutil.copytree(folder / "masks", masks)
    for path in sorted(masks.iterdir())[:drop]:
        path.unlink()
    if size is not None:
        for path in masks.iterdir():
            cv2.imwrite(str(path), cv2.resize(cv2.imread(str(path)), size))
    return masks


def _model_text(folder, edit):
    sparse = folder / "sparse"
    for path in sparse.glob("*.bin"):
        path.unlink()
    images = sparse / "images.txt"
    images.write_text(edit(images.read_text()))


def _text_model(folder):
    """The capture's model as a text model (so a fault can edit it)."""
    from ..io.colmap import read_colmap_model, write_colmap_model

    model = read_colmap_model(folder / "sparse")
    shutil.rmtree(folder / "sparse")
    write_colmap_model(folder / "sparse", model.cameras)


def _malformed(text):
    """The first image line's first quaternion value is not a number."""
    lines = text.splitlines()
    first = next(k for k, line in enumerate(lines) if line and not line.startswith("#"))
    fields = lines[first].split()
    lines[first] = " ".join([fields[0], "x"] + fields[2:])
    return "\n".join(lines) + "\n"


def _other_names(text):
    return "\n".join(line.replace(".jpg", "_other.jpg") for line in text.splitlines()) + "\n"


def _half_the_images(text):
    """The first half of the images (each a pose line and an empty points line)."""
    lines = text.splitlines()
    poses = [k for k, line in enumerate(lines) if line and not line.startswith("#")]
    keep = set(poses[:len(poses) // 2])
    return "\n".join(line for k, line in enumerate(lines)
                     if k in keep or line.startswith("#") or not line) + "\n"


#: An "argument" that runs the command with a file size limit of 1 kB (the result does not fit).
_FILE_SIZE_LIMIT = "<file size limit>"


@dataclasses.dataclass(frozen=True)
class _CtrlC:
    """An "argument" that presses Ctrl-C (SIGINT) once these progress messages showed, in
    this order."""

    after: tuple


#: Where Ctrl-C is pressed for each stage (the carving's first messages are the agreement's).
_STAGE_MESSAGES = [("the masks", ("% masks",)), ("the cameras", ("% cameras",)),
                   ("the mask agreement", ("agreeing masks",)),
                   ("the carving", ("masks agreed", "% carving")),
                   ("the segment graph", ("grow fronts",)), ("the topology", ("branches",)),
                   ("the final fit", ("rod: iteration",))]


#: ``(name, prepare(folder) -> (images, extra arguments), expected exit codes)``; ``folder`` is a
#: fresh copy of the clean capture. Outputs go to ``folder / "out"`` unless the fault names one.
FAULTS = [
    ("clean capture (the control)", lambda f: (f / "images", []), (0,)),
    ("missing folder", lambda f: (f / "nowhere", []), (2,)),
    ("empty folder", lambda f: ((f / "empty").mkdir() or f / "empty", []), (2,)),
    ("files that are not images", lambda f: (
        [p.write_bytes(b"not an image") for p in _frames(f)] and f / "images", []), (2,)),
    ("mixed sizes", lambda f: (cv2.imwrite(str(_frames(f)[3]), np.zeros((100, 120, 3),
                                                                       np.uint8))
                               and f / "images", []), (2,)),
    ("one frame", lambda f: (_keep_frames(f, 1) or f / "images", []), (2, 3)),
    ("two frames", lambda f: (_keep_frames(f, 2) or f / "images", []), (2, 3)),
    ("three views", lambda f: (_keep_frames(f, 3) or f / "images", []), (0, 3)),
    ("greyscale frames, no cable", lambda f: (_replace_frames(
        f, lambda i: np.full_like(i, 128)) or f / "images", []), (3,)),
    ("all-black frames", lambda f: (_replace_frames(f, np.zeros_like) or f / "images", []),
     (3,)),
    ("all-white frames", lambda f: (_replace_frames(
        f, lambda i: np.full_like(i, 255)) or f / "images", []), (3,)),
    ("a truncated JPEG", lambda f: (_truncate(_frames(f)[4]) or f / "images", []), (2,)),
    ("a corrupt JPEG (garbage inside)", lambda f: (_corrupt(_frames(f)[4]) or f / "images",
                                                   []), (0, 2, 3)),
    ("EXIF-rotated phone photos (the stored grid, as pycolmap reads it)", lambda f: (
        _rotated_by_exif(f) or f / "images", []), (0,)),
    ("PNG frames with alpha", lambda f: (_to_png(f, lambda i: cv2.cvtColor(
        i, cv2.COLOR_BGR2BGRA)) or f / "images", []), (0,)),
    ("16-bit PNG frames", lambda f: (_to_png(f, lambda i: i.astype(np.uint16) * 257)
                                     or f / "images", []), (0,)),
    ("CMYK JPEG frames", lambda f: (_to_cmyk(f) or f / "images", []), (0,)),
    ("huge frames (four of 8K: 7680x4320)", lambda f: (
        _keep_frames(f, 4) or _recropped(f, 7680, 4320, 16.0) or f / "images", []), (0,)),
    ("the cable leaving the frame in every view (the middle 60% kept)", lambda f: (
        _recropped(f, 288, 216, 1.0) or f / "images", []), (0, 3)),
    ("tiny frames (64x48), cameras estimated", lambda f: (
        _replace_frames(f, lambda i: cv2.resize(i, (64, 48))) or shutil.rmtree(f / "sparse")
        or f / "images", []), (2, 3)),
    ("frames of another size than the model's", lambda f: (
        _replace_frames(f, lambda i: cv2.resize(i, (640, 480))) or f / "images", []), (2,)),
    ("--masks with a mask missing", lambda f: (f / "images",
                                               ["--masks", _mask_folder(f, drop=1)]), (2,)),
    ("--masks of the wrong size", lambda f: (f / "images",
                                             ["--masks", _mask_folder(f, size=(240, 180))]),
     (2,)),
    ("a malformed COLMAP model", lambda f: (_text_model(f) or _model_text(
        f, _malformed) or f / "images", []), (2,)),
    ("a COLMAP model naming other images", lambda f: (_text_model(f) or _model_text(
        f, _other_names) or f / "images", []), (2,)),
    ("a COLMAP model missing half the images", lambda f: (_text_model(f) or _model_text(
        f, _half_the_images) or f / "images", []), (0,)),
    ("an existing output without --overwrite", lambda f: (
        (f / "out").mkdir() or (f / "out" / "result.json").write_text("mine")
        or f / "images", []), (2,)),
    ("an output in a folder that does not exist", lambda f: (
        f / "images", ["-o", f / "nowhere" / "result.json"]), (2,)),
    ("an output that is a folder", lambda f: (
        (f / "taken").mkdir() or f / "images", ["-o", f / "taken"]), (2,)),
    ("an output folder that may not be written in (/sys)", lambda f: (
        f / "images", ["-o", "/sys/result.json"]), (2,)),
    ("a full disk (a file size limit: no room for the result)", lambda f: (
        f / "images", [_FILE_SIZE_LIMIT]), (2,)),
] + [(f"Ctrl-C during {stage}", lambda f, after=after: (f / "images", [_CtrlC(after)]), (130,))
     for stage, after in _STAGE_MESSAGES]


def _snapshot(folder):
    """Every file's size and modification time under ``folder``."""
    return {path: (path.stat().st_size, path.stat().st_mtime_ns)
            for path in folder.rglob("*") if path.is_file()}


#: A run silent this long (seconds) is a hang: it is killed.
_HANG = 600.0


@dataclasses.dataclass
class _Run:
    """One fault's command, running."""

    name: str
    expected: tuple
    folder: Path
    before: dict
    process: subprocess.Popen
    waiting: list  # the progress messages still awaited before Ctrl-C
    interrupted: bool
    started: float = dataclasses.field(default_factory=time.perf_counter)
    stderr: bytes = b""
    seen: int = 0
    deadline: float = dataclasses.field(default_factory=lambda: time.monotonic() + _HANG)

    def read(self):
        """Read what the command wrote on stderr; False at its end. Presses Ctrl-C once
        every awaited message showed, in order."""
        chunk = os.read(self.process.stderr.fileno(), 1 << 16)
        if not chunk:
            return False
        self.stderr += chunk
        self.deadline = time.monotonic() + _HANG
        while self.waiting and (found := self.stderr.find(self.waiting[0], self.seen)) >= 0:
            self.seen = found + len(self.waiting.pop(0))  # the next is looked for after it
            if not self.waiting:
                self.process.send_signal(signal.SIGINT)
        return True


def _start_fault(number, fault, clean, work):
    """Fault ``number`` prepared in a fresh copy of the ``clean`` capture and its command
    started."""
    name, prepare, expected = fault
    folder = work / f"capture{number}"
    shutil.copytree(clean, folder)
    images, extra = prepare(folder)
    size_limit = _FILE_SIZE_LIMIT in extra
    interrupt = next((value for value in extra if isinstance(value, _CtrlC)), None)
    extra = [str(value) for value in extra if value != _FILE_SIZE_LIMIT and value is not interrupt]
    if "--cameras" not in extra and (folder / "sparse").is_dir():
        extra = ["--cameras", str(folder / "sparse")] + extra
    if "-o" not in extra:
        (folder / "out").mkdir(exist_ok=True)
        extra += ["-o", str(folder / "out" / "result.json")]
    before = _snapshot(folder)
    command = [sys.executable, "-m", "engine"] + ([] if interrupt else ["-q"]) + [
        "reconstruct", str(images), *extra]

    def limit():
        # a run started in the background inherits an ignored SIGINT, and Python then never
        # turns Ctrl-C into KeyboardInterrupt: give it the default back
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        if size_limit:
            resource.setrlimit(resource.RLIMIT_FSIZE, (1024, 1024))

    # (the runs are started from this thread alone, so preexec_fn is safe)
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                               cwd=Path(__file__).resolve().parents[2], preexec_fn=limit)
    return _Run(name, expected, folder, before, process,
                [m.encode() for m in interrupt.after] if interrupt else [], interrupt is not None)


def _finished(run, work):
    """The row of a run whose command ended (its copy of the capture removed)."""
    run.process.stderr.close()
    returncode = run.process.wait()
    seconds = time.perf_counter() - run.started
    stderr = run.stderr.decode(errors="replace")
    folder = run.folder
    after = _snapshot(folder)
    changed = sorted(str(path.relative_to(folder)) for path in run.before
                     if after.get(path) != run.before[path])
    added = sorted(str(path.relative_to(folder)) for path in after if path not in run.before)
    lines = [line for line in re.split(r"[\r\n]", stderr) if line.strip()
             and not line.startswith("[")]  # (the progress bar's lines)
    message = next((line for line in (reversed(lines) if run.interrupted else lines)
                    if not line.startswith("warning:")), "")
    traceback = "Traceback" in stderr or returncode == 4
    untouched = not changed and (returncode == 0 or not added)
    shutil.rmtree(folder, ignore_errors=True)
    message = message.replace(str(folder), "…/capture").replace(str(work), "…")
    return {"fault": run.name, "exit": returncode,
            "expected": "/".join(map(str, run.expected)),
            "ok": "yes" if returncode in run.expected and not traceback and untouched else "NO",
            "traceback": "yes" if traceback else "no",
            "nothing_changed": "yes" if untouched else f"no: {', '.join(changed + added)[:60]}",
            "message": message[:110].replace("|", "/"),
            "seconds": round(seconds, 1)}


def _run_faults(clean, work, workers, progress):
    """The rows of every fault, ``workers`` at a time, each command watched for its messages
    and for silence (:data:`_HANG`); no command is left running if one cannot start."""
    rows = [None] * len(FAULTS)
    waiting, running, done = list(enumerate(FAULTS)), {}, 0
    try:
        while waiting or running:
            while waiting and len(running) < workers:
                number, fault = waiting.pop(0)
                if progress is not None:
                    progress(done / len(FAULTS), fault[0])
                run = _start_fault(number, fault, clean, work)
                running[run.process.stderr.fileno()] = (number, run)
            timeout = max(min(run.deadline for _, run in running.values()) - time.monotonic(),
                          0.0)
            ready, _, _ = select.select(list(running), [], [], timeout)
            for descriptor, (number, run) in list(running.items()):
                if descriptor in ready:
                    ended = not run.read()
                else:  # silent past its deadline: a hang
                    ended = time.monotonic() >= run.deadline
                    if ended:
                        run.process.kill()
                if ended:
                    del running[descriptor]
                    rows[number] = _finished(run, work)
                    done += 1
    finally:  # a fault that could not start (or Ctrl-C): no command left behind
        for _, run in running.values():
            run.process.kill()
            run.process.wait()
            run.process.stderr.close()
    return rows


def bench_faults(*, workers=2, progress=None):
    """Run every fault of :data:`FAULTS`; one row each, in their order.

    Parameters
    ----------
    workers : int, optional
        Faults run at once (each command in its own process, on its own copy of the capture).
    progress : callable, optional
        ``progress(fraction, message)``.

    Returns
    -------
    list of dict
    """
    if workers < 1:
        raise ValueError(f"workers must be at least 1, not {workers}")
    with tempfile.TemporaryDirectory(prefix="bench_faults_") as work:
        work = Path(work)
        rows = _run_faults(_capture(work / "clean"), work, workers, progress)
    if progress is not None:
        progress(1.0, "done")
    return rows
