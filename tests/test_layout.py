"""The project's layering rules, checked on the tree: the engine free of Blender, relative imports,
the data flow's direction between the engine's packages, developer code apart from the runtime."""

import ast
import shutil
import subprocess
import sys

import pytest

from conftest import ROOT

ENGINE_FILES = sorted((ROOT / "engine").rglob("*.py"))
ADDON_FILES = sorted((ROOT / "addon").rglob("*.py"))
BLENDER_MODULES = {"bpy", "bpy_extras", "mathutils", "bmesh", "gpu", "blf", "addon"}


#: Developer code: never imported by the runtime, never in the extension's zip.
DEVELOPER = ("engine.synthetic", "engine.evaluation", "engine.bench")
#: The runtime's packages in the data flow's order: a module imports only from its own rank or
#: an earlier one (errors, progress and settings are what every rank reports and is tuned with;
#: threads are how every rank spreads its work over the cores).
RANKS = {"engine.errors": 0, "engine.progress": 0, "engine.settings": 0, "engine.__version__": 0,
         "engine.threads": 0,
         "engine.geometry": 1, "engine.io": 2,
         "engine.stages": 3, "engine.pipeline": 4, "engine.batch": 4, "engine.cli": 5,
         "engine": 6,
         "engine.__main__": 6}


def module_name(path):
    """``engine.stages.carving`` of ``ROOT/engine/stages/carving.py`` (a package: its name)."""
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(path):
    """(level, module) of every import statement in ``path``: ``module`` absolute (relative ones
    resolved against ``path``'s package; ``from . import x`` gives ``package.x``), or for a
    relative import reaching above the top package, None."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module_name(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield 0, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                yield 0, node.module
                continue
            if node.level > len(package):
                yield node.level, None
                continue
            base = package[:len(package) - node.level + 1]
            if node.module:
                yield node.level, ".".join(base + [node.module])
            else:
                for alias in node.names:
                    yield node.level, ".".join(base + [alias.name])


def rank(module):
    """The runtime rank of an engine module (None for developer code)."""
    for prefix in sorted(RANKS, key=len, reverse=True):
        if module == prefix or module.startswith(prefix + "."):
            return RANKS[prefix]
    return None


@pytest.mark.parametrize("path", ENGINE_FILES, ids=module_name)
def test_engine_never_imports_blender_or_the_addon(path):
    for level, module in imported_modules(path):
        assert module is not None, f"{path.name} reaches outside engine/ with a relative import"
        assert not (level == 0 and module.split(".")[0] in BLENDER_MODULES), \
            f"{path.name} imports {module}"
        assert level == 0 or module.startswith("engine"), \
            f"{path.name} reaches outside engine/ with a relative import"


RUNTIME_FILES = [path for path in ENGINE_FILES if not module_name(path).startswith(DEVELOPER)]


@pytest.mark.parametrize("path", RUNTIME_FILES, ids=module_name)
def test_the_runtime_follows_the_data_flow_and_never_imports_developer_code(path):
    own = rank(module_name(path))
    for level, module in imported_modules(path):
        if level == 0:
            continue
        assert not module.startswith(DEVELOPER), f"{module_name(path)} imports {module}"
        assert rank(module) <= own, \
            f"{module_name(path)} (rank {own}) imports {module} (rank {rank(module)}), " \
            "against the data flow"


def test_the_runtime_imports_and_runs_without_the_developer_packages(tmp_path):
    # What the extension's zip holds (the manifest leaves the developer packages out): every
    # runtime module imports and the command line works, with no bench.
    shutil.copytree(ROOT / "engine", tmp_path / "engine",
                    ignore=shutil.ignore_patterns("__pycache__", *(name.split(".")[1]
                                                                   for name in DEVELOPER)))
    script = """
import importlib, pkgutil
import engine
from engine.cli.main import build_parser
for info in pkgutil.walk_packages(engine.__path__, "engine."):
    if info.name != "engine.__main__":
        importlib.import_module(info.name)
print(sorted(build_parser()._subparsers._group_actions[0].choices))
"""
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         cwd=tmp_path, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split("\n")[0] == "['batch', 'cameras', 'reconstruct', 'segment']"
    assert sorted(path.name for path in (tmp_path / "engine").iterdir()
                  if path.is_dir()) == ["cli", "geometry", "io", "stages"]


@pytest.mark.parametrize("path", ENGINE_FILES + ADDON_FILES, ids=module_name)
def test_own_packages_are_imported_relatively(path):
    # Inside Blender the package is bl_ext.<repo>.cable_reconstruction: absolute imports break.
    for level, module in imported_modules(path):
        assert not (level == 0 and module.split(".")[0] in ("engine", "addon",
                                                           "cable_reconstruction")), \
            f"{path.name} imports {module} absolutely"


#: The longest a runtime function may be, its docstring aside: longer ones do several jobs.
LONGEST_FUNCTION = 60


@pytest.mark.parametrize("path", RUNTIME_FILES, ids=module_name)
def test_runtime_functions_are_short(path):
    tree = ast.parse(path.read_text(), filename=str(path))
    long = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            first = node.body[0]
            documented = isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) \
                and isinstance(first.value.value, str)
            start = first.end_lineno + 1 if documented else first.lineno
            if node.end_lineno - start + 1 > LONGEST_FUNCTION:
                long.append(f"{node.name} ({node.end_lineno - start + 1} lines)")
    assert not long, f"{module_name(path)}: {', '.join(long)}"


def test_library_code_never_prints():
    command_lines = ("engine/cli/main.py", "engine/bench/cli.py", "engine/__main__.py",
                     "addon/batch_command.py",
                     "engine/evaluation/outline_training.py")  # its main() is a command
    for path in ENGINE_FILES + ADDON_FILES:
        if path.relative_to(ROOT).as_posix() in command_lines:
            continue
        tree = ast.parse(path.read_text())
        calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)
                 and isinstance(n.func, ast.Name) and n.func.id == "print"]
        assert not calls, f"{path.name} prints"
