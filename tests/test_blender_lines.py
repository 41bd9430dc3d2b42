"""The engine gives the same reconstruction in every Blender line (README: Supported Blender
versions): numpy 1.26 on Python 3.11 (Blender 4.5 LTS) and numpy 2 on Python 3.13 (5.2, 5.3).

Each line's environment is set up by the Makefile (``make test-all``: ``.venv-4.5``,
``.venv-5.2``, then ``.venv``, the newest, whose run compares itself with the others)."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT
from engine import read_result

SAMPLE = ROOT / "samples" / "sequence"
#: Each line's environment folder and the Blender it stands for.
LINES = {".venv-4.5": "4.5", ".venv-5.2": "5.2", ".venv": "5.3"}


def _other_lines():
    """The Pythons of the lines set up besides the one running the tests."""
    here = Path(sys.prefix).resolve()
    return [ROOT / folder / "bin" / "python" for folder in LINES
            if (ROOT / folder / ".requirements-installed").is_file()
            and (ROOT / folder).resolve() != here]


def _versions(python):
    run = subprocess.run([str(python), "-c", "import sys, numpy; print(sys.version.split()[0], "
                          "numpy.__version__)"], capture_output=True, text=True, check=True)
    return run.stdout.split()


def _reconstruct(python, output):
    """The sample reconstructed with its true cameras, as a pipeline would, in ``python``."""
    run = subprocess.run([str(python), "-m", "engine", "reconstruct", str(SAMPLE / "images"),
                          "--cameras", str(SAMPLE / "sparse"), "-o", str(output), "-q"],
                         cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    return read_result(output)


def _strands(result):
    """Each crossing's over and under strand (path, index)."""
    return [(c.over.path, c.over.index, c.under.path, c.under.index) for c in result.crossings]


@pytest.mark.skipif(not _other_lines(),
                    reason="no other Blender line is set up (make test-all sets up all three)")
def test_the_sample_reconstructs_to_the_same_points_in_every_line(tmp_path):
    here = _reconstruct(sys.executable, tmp_path / "here.json")
    for python in _other_lines():
        versions = (_versions(sys.executable), _versions(python))
        there = _reconstruct(python, tmp_path / f"{python.parent.parent.name}.json")
        assert there.radius == pytest.approx(here.radius, rel=1e-6, abs=0), versions
        assert len(there.paths) == len(here.paths), versions
        for mine, theirs in zip(here.paths, there.paths):
            assert len(theirs.points) == len(mine.points), versions
            gap = np.abs(np.asarray(theirs.points) - np.asarray(mine.points)).max()
            assert gap <= 1e-6 * here.radius, (versions, gap / here.radius)
        assert _strands(there) == _strands(here), versions
