"""The extension as users get it: Blender's validator, builder and installer on our package."""

import json
import os
import re
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest

import package  # tools/package.py
from conftest import ROOT
from engine import __version__, read_result, write_result
from engine.io.ground_truth import read_ground_truth
from engine.pipeline import reconstruct
from engine.stages.bezier import fit_result_curves
from engine.synthetic.scene import SceneSpec, make_scene, write_scene

MANIFEST = tomllib.loads((ROOT / "blender_manifest.toml").read_text())


def test_blenders_validator_accepts_the_repository():
    builder, tags = package.blender_tools()
    run = subprocess.run([sys.executable, str(builder), "validate", str(ROOT),
                          f"--valid-tags={tags}"], capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr


def test_manifest_matches_the_engine_and_supported_blenders():
    assert MANIFEST["id"] == package.EXTENSION_ID
    assert MANIFEST["version"] == __version__
    assert MANIFEST["blender_version_min"] == "4.5.0"
    assert MANIFEST["blender_version_max"] == "5.4.0"  # exclusive: 5.3.x is the newest tested
    assert set(MANIFEST["platforms"]) == set(package.PLATFORM_TAGS)
    assert "files" in MANIFEST["permissions"]
    excluded = MANIFEST["build"]["paths_exclude_pattern"]
    for folder in ("/tests/", "/samples/", "/tools/", "/build/", "/dist/"):
        assert folder in excluded


def test_root_init_is_the_two_line_entry_point():
    lines = (ROOT / "__init__.py").read_text().strip().splitlines()
    assert lines[0] == "from .addon import register, unregister  # noqa: F401"
    assert len(lines) == 2


def _fake_wheel_cache(folder):
    """Empty files named like each platform's real wheels (the builder only sorts by name):
    one per Python for the compiled ones, one abi3 wheel for OpenCV, one pure for networkx."""
    platforms = {"linux-x64": "manylinux_2_28_x86_64", "macos-arm64": "macosx_14_0_arm64",
                 "windows-x64": "win_amd64"}
    for platform, tag in platforms.items():
        (folder / platform).mkdir(parents=True)
        for name, version in package.runtime_requirements():
            wheel_name = re.sub(r"[-_.]+", "_", name).lower()
            if name == "networkx":
                tags = ["py3-none-any"]
            elif name.startswith("opencv"):
                tags = [f"cp37-abi3-{tag}"]
            else:
                tags = [f"cp{v}-cp{v}-{tag}" for v in ("311", "313")]
            for wheel_tag in tags:
                (folder / platform / f"{wheel_name}-{version}-{wheel_tag}.whl").write_bytes(b"")


#: Developer code that never ships in the extension.
DEVELOPER_PACKAGES = [["engine", name] for name in ("synthetic", "evaluation", "bench")]


def test_one_zip_per_platform_with_its_wheels_for_every_python(tmp_path):
    _fake_wheel_cache(tmp_path / "cache")
    zips = package.build(list(package.PLATFORM_TAGS), tmp_path / "dist",
                         cache=tmp_path / "cache", stage_root=tmp_path / "stage")
    assert len(zips) == 3
    names = {name for name, _ in package.runtime_requirements()}
    assert "numpy" not in names
    for path, platform in zip(zips, package.PLATFORM_TAGS):
        with zipfile.ZipFile(path) as archive:
            files = archive.namelist()
            manifest = tomllib.loads(archive.read("blender_manifest.toml").decode())
        wheels = [f for f in files if f.endswith(".whl")]
        # scipy and pycolmap once per Python, OpenCV's abi3 wheel and networkx once
        assert len(wheels) == 2 * len(names) - 2, wheels
        for python in package.PYTHONS:
            for name in names:
                prefix = re.sub(r"[-_.]+", "_", name).lower() + "-"
                served = [w for w in wheels if Path(w).name.startswith(prefix)
                          and package.serves(w, python)]
                assert len(served) == 1, (name, python, wheels)
        marker = {"linux-x64": "manylinux", "macos-arm64": "macosx", "windows-x64": "win_amd64"}
        for wheel in wheels:
            assert marker[platform] in wheel or wheel.endswith("py3-none-any.whl"), wheel
        generated = manifest["build"]["generated"]  # what Blender reads for a split build
        assert generated["platforms"] == [platform]
        assert sorted(generated["wheels"]) == sorted(f"./{w}" for w in wheels)
        assert "__init__.py" in files and "addon/__init__.py" in files
        assert "engine/io/result.py" in files
        assert not [f for f in files if f.split("/")[0] in ("tests", "samples", "tools")]
        # the developer packages stay out; the installer test below runs without them
        assert "engine/stages/topology/resolve.py" in files and "engine/cli/main.py" in files
        assert "engine/stages/outline_weights.json" in files  # data the runtime reads
        assert not [f for f in files if f.split("/")[:2] in DEVELOPER_PACKAGES], files
        assert not [f for f in files if "__pycache__" in f]


def test_a_wheel_serves_the_pythons_blender_would_install_it_on():
    assert package.serves("scipy-1.16.3-cp311-cp311-win_amd64.whl", "3.11")
    assert not package.serves("scipy-1.16.3-cp311-cp311-win_amd64.whl", "3.13")
    assert package.serves("pycolmap-4.2.1-cp313-cp313-macosx_14_0_arm64.whl", "3.13")
    abi3 = "opencv_python_headless-4.11.0.86-cp37-abi3-manylinux_2_17_x86_64.whl"
    assert package.serves(abi3, "3.11") and package.serves(abi3, "3.13")
    assert not package.serves("x-1.0-cp314-abi3-win_amd64.whl", "3.13")
    assert package.serves("networkx-3.6.1-py3-none-any.whl", "3.13")


@pytest.fixture(scope="module")
def linux_zip(tmp_path_factory):
    """The real linux-x64 zip; wheels are downloaded once into .cache/wheels and reused."""
    (path,) = package.build(["linux-x64"], tmp_path_factory.mktemp("dist"),
                            stage_root=tmp_path_factory.mktemp("stage"))
    return path


def test_installed_through_blenders_installer(linux_zip, tmp_path):
    truth = read_ground_truth(ROOT / "samples" / "sequence" / "ground_truth.json")
    sample = write_result(truth.as_result(), tmp_path / "sample_cable.json")
    capture = write_scene(make_scene(SceneSpec(crossings=1, seed=5, views=16, width=640,
                                               height=480, image_format="jpg")),
                          tmp_path / "loop")
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    run = subprocess.run(
        [sys.executable, str(ROOT / "tests" / "blender_scripts" / "install_extension.py"),
         str(linux_zip), str(sample), str(capture), str(tmp_path / "loop.blend")],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    lines = [line for line in run.stdout.splitlines() if line.startswith("REPORT ")]
    assert run.returncode == 0 and lines, run.stdout[-3000:] + run.stderr[-3000:]
    report = json.loads(lines[-1][len("REPORT "):])
    assert report["install"] == ["FINISHED"] and report["enabled"]
    assert "CABLE_RECON_OT_import_result" in report["operators"]
    assert report["panel"] and report["import_menu"]
    assert report["wheels"] == {"cv2": True, "pycolmap": True, "scipy": True, "networkx": True}
    assert report["import_result"] == ["FINISHED"]
    expected = read_result(sample)
    assert report["curve"]["name"] == "sample_cable"
    assert report["curve"]["points"] == sum(len(p.points) for p in expected.paths)
    assert report["curve"]["bevel"] == pytest.approx(expected.radius)
    # Reconstruct through the installed add-on agrees with the engine's API on the same capture
    assert report["reconstruct"] == ["FINISHED"]
    (curve,) = report["reconstructed"]
    api = reconstruct(capture / "images", cameras=capture / "sparse")
    curves, fit = fit_result_curves(api)
    assert curve["name"] == "loop" and curve["type"] == "BEZIER"
    assert curve["bevel"] == pytest.approx(api.radius, rel=1e-5)
    assert curve["control_points"] == curve["reported"] == fit["control_points"]
    np.testing.assert_allclose(curve["knots"], curves[0].knots, atol=1e-4 * api.radius)
    assert curve["crossings"] == len(api.crossings) == 1
    assert report["batch_exit"] == 0 and report["batch_objects"] == ["loop"]
    assert report["batch_folder_exit"] == 0 and report["batch_folder"] == ["loop.blend"]


def test_loading_the_checkout_as_the_package_leaves_no_folder_behind():
    # tests and tools link the checkout into a temporary folder; a run must not leave it
    script = ("from pathlib import Path; from blender_package import load_addon_package; "
              "print(Path(load_addon_package().__file__).parent.parent)")
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT / "tools")})
    assert run.returncode == 0, run.stderr
    link_dir = Path(run.stdout.strip().splitlines()[-1])
    assert link_dir.name.startswith("cable_recon_pkg_") and not link_dir.exists()
    assert (ROOT / "engine").is_dir()  # the link went, not what it points to
