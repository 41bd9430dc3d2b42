"""Load this checkout as the add-on package inside the bpy module (for tools and tests).

Inside Blender the extension is the package ``bl_ext.<repo>.cable_reconstruction``; here the
checkout is linked as a top-level package of the same name so its relative imports resolve.
"""

import atexit
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
    link = link_dir / PACKAGE
    os.symlink(ROOT, link, target_is_directory=True)
    atexit.register(_remove_link, link)
    sys.path.insert(0, str(link_dir))
    return importlib.import_module(PACKAGE)


def _remove_link(link):
    """Remove the link (not what it points to) and its temporary folder at exit."""
    link.unlink(missing_ok=True)
    try:
        link.parent.rmdir()
    except OSError:  # something else was put there: leave it
        pass
