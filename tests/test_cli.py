"""`python -m engine` as a pipeline runs it: version, help, exit codes."""

import subprocess
import sys

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
