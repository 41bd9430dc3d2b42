"""Cable Reconstruction engine: images of a cable to one continuous 3D centreline.

Pure NumPy / SciPy / OpenCV / pycolmap / networkx; it never imports Blender, so it runs from
the command line (``python -m engine``), in a pipeline, or inside the Blender extension.
"""

from .camera import CAMERA_MODELS, Camera
from .colmap_model import ColmapModel, read_colmap_model, write_colmap_model
from .errors import Cancelled, InputError, ReconstructionError
from .ground_truth import GroundTruth, TrueCrossing, read_ground_truth, write_ground_truth
from .result import (RESULT_FORMAT, CablePath, Crossing, Result, StrandRef, read_result,
                     write_result)

__version__ = "0.1.0"

__all__ = [
    "__version__", "CAMERA_MODELS", "Camera", "ColmapModel", "read_colmap_model",
    "write_colmap_model", "Cancelled", "InputError", "ReconstructionError", "RESULT_FORMAT",
    "CablePath", "Crossing", "Result", "StrandRef", "read_result", "write_result",
    "GroundTruth", "TrueCrossing", "read_ground_truth", "write_ground_truth", "Metrics",
    "align_result_to_truth", "evaluate",
]

_LAZY = {"Metrics", "align_result_to_truth", "evaluate"}  # scipy: not needed to import results


def __getattr__(name):
    if name in _LAZY:
        from . import metrics

        return getattr(metrics, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
