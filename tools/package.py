"""Build the extension zips with Blender's own builder (``make package``).

For each platform: download the runtime wheels (``requirements.txt``; numpy is never bundled,
Blender ships its own) for each Python a supported Blender embeds (:data:`PYTHONS`: 3.11 for
Blender 4.5 LTS and 5.0, 3.13 for 5.1 to 5.3) into a cache, stage the extension with those
wheels written into its manifest, check it with ``blender_ext.py validate`` and build one zip
per platform with ``blender_ext.py build --split-platforms``. The builder and validator are
the ones inside the installed ``bpy`` wheel.

Each zip carries the wheels of both Pythons; when the extension is enabled, Blender installs
only those whose tags match its own Python (``_extensions_wheel_filter_for_this_system`` in
``bl_pkg/bl_extension_ops.py``, the same from 4.5 to 5.3): a ``cp311`` wheel in 4.5, a
``cp313`` one in 5.3, an ``abi3`` or pure one (OpenCV, networkx) in both.

    python tools/package.py [--platforms linux-x64,macos-arm64,windows-x64] [--output-dir dist]
"""

import argparse
import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
EXTENSION_ID = "cable_reconstruction"
#: What the zip is made of; the manifest's [build] excludes still apply on top.
EXTENSION_FILES = ("__init__.py", "blender_manifest.toml", "LICENSE", "addon", "engine")
#: Blender platform name -> pip --platform tags that Blender's Python on it accepts.
PLATFORM_TAGS = {
    "linux-x64": ["manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"],
    "macos-arm64": [f"macosx_{v}_0_arm64" for v in (14, 13, 12, 11)],
    "windows-x64": ["win_amd64"],
}
NEVER_BUNDLED = {"numpy"}  # Blender ships its own
#: The Pythons of the supported Blenders (blender_manifest.toml): wheels for each are bundled.
PYTHONS = ("3.11", "3.13")
DEFAULT_CACHE = Path(os.environ.get("CABLE_RECON_WHEEL_CACHE", ROOT / ".cache" / "wheels"))


def blender_tools():
    """Paths of ``blender_ext.py`` and Blender's tag list inside the installed bpy wheel."""
    spec = importlib.util.find_spec("bpy")  # finds the package without loading Blender
    if spec is None or not spec.submodule_search_locations:
        sys.exit("bpy is not installed: run `make setup` first")
    bpy_dir = Path(list(spec.submodule_search_locations)[0])
    builder = sorted(bpy_dir.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    tags = sorted(bpy_dir.glob("*/scripts/modules/_bpy_internal/extensions/tags.py"))
    if not builder or not tags:
        sys.exit(f"Blender's extension builder was not found under {bpy_dir}")
    return builder[-1], tags[-1]


def runtime_requirements(path=ROOT / "requirements.txt"):
    """``[(name, version)]`` pinned in requirements.txt, numpy left out."""
    pins = []
    for line in path.read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        match = re.fullmatch(r"([A-Za-z0-9_.-]+)==([A-Za-z0-9_.+-]+)", line)
        if not match:
            sys.exit(f"{path}: every runtime requirement must be pinned as name==version: {line!r}")
        if match.group(1).lower() not in NEVER_BUNDLED:
            pins.append((match.group(1), match.group(2)))
    return pins


def _wheel_prefix(name, version):
    return f"{re.sub(r'[-_.]+', '_', name).lower()}-{version}-"


def serves(wheel, python):
    """Whether a wheel (file name) installs on CPython ``python`` ("3.11"), as Blender's filter
    decides: ``cpXY`` of that version, ``abi3`` from its version up, or pure ``py3``."""
    python_tags, abi = Path(wheel).stem.split("-")[-3:-1]
    version = int(python.replace(".", ""))
    for tag in python_tags.split("."):
        if tag == "py3" or tag == f"cp{version}":
            return True
        if abi == "abi3" and tag.startswith("cp") and int(tag[2:]) <= version:
            return True
    return False


def platform_wheels(platform, cache, pythons=PYTHONS):
    """Wheels of every runtime requirement for ``platform`` and each of ``pythons``, downloaded
    once into ``cache`` (a wheel that serves several Pythons is listed once)."""
    folder = Path(cache) / platform
    folder.mkdir(parents=True, exist_ok=True)
    wheels = []
    for name, version in runtime_requirements():
        prefix = _wheel_prefix(name, version)
        for python in pythons:
            found = [w for w in folder.glob("*.whl")
                     if w.name.lower().startswith(prefix) and serves(w.name, python)]
            if not found:
                command = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
                           "--only-binary=:all:", "--python-version", python,
                           "--implementation", "cp", "--dest", str(folder), f"{name}=={version}"]
                for tag in PLATFORM_TAGS[platform]:
                    command += ["--platform", tag]
                print(f"downloading {name}=={version} for {platform}, Python {python}",
                      file=sys.stderr)
                subprocess.run(command, check=True)
                found = [w for w in folder.glob("*.whl")
                         if w.name.lower().startswith(prefix) and serves(w.name, python)]
            if len(found) != 1:
                sys.exit(f"expected one {name} {version} wheel for {platform} and Python {python}"
                         f" in {folder}, found {[w.name for w in found]}")
            if found[0] not in wheels:
                wheels.append(found[0])
    return wheels


def write_manifest(source, destination, platforms, wheels):
    """Copy the manifest, declaring ``platforms`` and listing ``wheels`` (paths in the zip)."""
    text = source.read_text()
    listed = ", ".join(f'"{p}"' for p in platforms)
    wheel_lines = "".join(f'  "./wheels/{w.name}",\n' for w in wheels)
    replacement = f"platforms = [{listed}]\nwheels = [\n{wheel_lines}]"
    text, count = re.subn(r"^platforms = \[[^\]]*\]", lambda _: replacement, text,
                          flags=re.MULTILINE)
    if count != 1:
        sys.exit(f"{source}: expected one `platforms = [...]` line")
    destination.write_text(text)


def stage(platforms, wheels, folder):
    """A clean copy of the extension with its wheels, ready for Blender's builder."""
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    for name in EXTENSION_FILES:
        source = ROOT / name
        if source.is_dir():
            shutil.copytree(source, folder / name,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        elif name != "blender_manifest.toml":
            shutil.copy2(source, folder / name)
    (folder / "wheels").mkdir()
    for wheel in wheels:
        shutil.copy2(wheel, folder / "wheels" / wheel.name)
    write_manifest(ROOT / "blender_manifest.toml", folder / "blender_manifest.toml",
                   platforms, wheels)
    return folder


def build(platforms, output_dir, *, cache=DEFAULT_CACHE, stage_root=ROOT / "build" / "stage"):
    """Validate and build one zip per platform; returns the zip paths."""
    unknown = [p for p in platforms if p not in PLATFORM_TAGS]
    if unknown:
        sys.exit(f"unknown platform(s) {unknown}; choose from {list(PLATFORM_TAGS)}")
    builder, tags = blender_tools()
    wheels = {}  # by file name: a pure-Python wheel serves every platform once
    for platform in platforms:
        for wheel in platform_wheels(platform, cache):
            wheels.setdefault(wheel.name, wheel)
    staged = stage(platforms, list(wheels.values()),
                   Path(stage_root) / "+".join(platforms) / EXTENSION_ID)
    output_dir = Path(output_dir).resolve()
    output_dir.mkdir(parents=True, exist_ok=True)
    python = [sys.executable, str(builder)]
    subprocess.run([*python, "validate", str(staged), f"--valid-tags={tags}"], check=True)
    subprocess.run([*python, "build", "--source-dir", str(staged), "--output-dir",
                    str(output_dir), "--split-platforms", f"--valid-tags={tags}"], check=True)
    version = re.search(r'^version = "([^"]+)"', (staged / "blender_manifest.toml").read_text(),
                        flags=re.MULTILINE).group(1)
    zips = [output_dir / f"{EXTENSION_ID}-{version}-{p.replace('-', '_')}.zip" for p in platforms]
    for path in zips:
        if not path.is_file():
            sys.exit(f"the builder did not write {path}")
        subprocess.run([*python, "validate", str(path), f"--valid-tags={tags}"], check=True)
    return zips


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--platforms", default=",".join(PLATFORM_TAGS),
                        help="comma-separated Blender platforms (default: all three)")
    parser.add_argument("--output-dir", default=str(ROOT / "dist"))
    parser.add_argument("--wheel-cache", default=str(DEFAULT_CACHE))
    args = parser.parse_args(argv)
    zips = build(args.platforms.split(","), args.output_dir, cache=args.wheel_cache)
    for path in zips:
        print(path)


if __name__ == "__main__":
    main()
