"""Load this checkout as the add-on package inside the bpy module (for tools and tests).

Inside Blender the extension is the package ``bl_ext.<repo>.cable_reconstruction``; here the
checkout is linked as a top-level package of the same name so its relative imports resolve.
"""

import importlib
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "cable_reconstruction"


def load_addon_package():
    """Import the checkout as ``cable_reconstruction`` and return the module (not registered)."""
    if PACKAGE in sys.modules:
        return sys.modules[PACKAGE]
    link_dir = Path(tempfile.mkdtemp(prefix="cable_recon_pkg_"))
    os.symlink(ROOT, link_dir / PACKAGE, target_is_directory=True)
    sys.path.insert(0, str(link_dir))
    return importlib.import_module(PACKAGE)
