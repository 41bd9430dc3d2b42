"""The project's layering rules, checked on the tree (engine free of Blender, relative imports)."""

import ast

import pytest

from conftest import ROOT

ENGINE_FILES = sorted((ROOT / "engine").rglob("*.py"))
ADDON_FILES = sorted((ROOT / "addon").rglob("*.py"))
BLENDER_MODULES = {"bpy", "bpy_extras", "mathutils", "bmesh", "gpu", "blf", "addon"}


def imported_modules(path):
    """(level, top-level module name) of every import statement in ``path``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield 0, alias.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom):
            yield node.level, (node.module or "").split(".")[0]


@pytest.mark.parametrize("path", ENGINE_FILES, ids=lambda p: p.name)
def test_engine_never_imports_blender_or_the_addon(path):
    for level, module in imported_modules(path):
        assert not (level == 0 and module in BLENDER_MODULES), f"{path.name} imports {module}"
        assert not (level >= 2), f"{path.name} reaches outside engine/ with a relative import"


@pytest.mark.parametrize("path", ENGINE_FILES + ADDON_FILES, ids=lambda p: p.name)
def test_own_packages_are_imported_relatively(path):
    # Inside Blender the package is bl_ext.<repo>.cable_reconstruction: absolute imports break.
    for level, module in imported_modules(path):
        assert not (level == 0 and module in ("engine", "addon", "cable_reconstruction")), \
            f"{path.name} imports {module} absolutely"


def test_library_code_never_prints():
    for path in ENGINE_FILES + ADDON_FILES:
        if path.name in ("cli.py", "__main__.py", "batch_command.py"):  # command lines
            continue
        tree = ast.parse(path.read_text())
        calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)
                 and isinstance(n.func, ast.Name) and n.func.id == "print"]
        assert not calls, f"{path.name} prints"
