"""Cable Reconstruction engine: images of a cable to one continuous 3D centreline.

Pure NumPy / SciPy / OpenCV / pycolmap / networkx; it never imports Blender, so it runs from
the command line (``python -m engine``), in a pipeline, or inside the Blender extension.
"""

from .camera import CAMERA_MODELS, Camera
from .colmap_model import ColmapModel, read_colmap_model, write_colmap_model
from .errors import Cancelled, InputError, OutputError, ReconstructionError
from .ground_truth import GroundTruth, TrueCrossing, read_ground_truth, write_ground_truth
from .result import (RESULT_FORMAT, CablePath, Crossing, Result, StrandRef, read_result,
                     write_result)

__version__ = "0.1.0"

#: Stage APIs, imported on first use (scipy, OpenCV and pycolmap are not needed to read a
#: result): name -> module.
_LAZY = {
    "Metrics": "metrics", "align_result_to_truth": "metrics", "evaluate": "metrics",
    "SegmentationSettings": "segmentation", "segment_frame": "segmentation",
    "auto_colour": "segmentation", "ColourRange": "segmentation",
    "CameraEstimationSettings": "camera_estimation", "estimate_cameras": "camera_estimation",
    "MaskAgreementSettings": "mask_agreement", "agree_masks": "mask_agreement",
    "CarvingSettings": "carving", "VoxelGrid": "carving", "carve": "carving",
    "SegmentGraphSettings": "segment_graph", "SegmentGraph": "segment_graph",
    "extract_segment_graph": "segment_graph",
    "extract_segment_graph_from_voxels": "segment_graph",
    "RodSettings": "rod", "Rod": "rod", "solve_rod": "rod",
    "RodFitSettings": "rod_fit", "RodFit": "rod_fit", "fit_rod": "rod_fit",
    "ImageEvidence": "rod_fit", "Contact": "rod_fit", "Voxels": "rod_fit",
    "TopologySettings": "topology", "resolve_topology": "topology",
    "PipelineSettings": "pipeline", "Reconstruction": "pipeline", "reconstruct": "pipeline",
    "run_reconstruction": "pipeline",
}

__all__ = [
    "__version__", "CAMERA_MODELS", "Camera", "ColmapModel", "read_colmap_model",
    "write_colmap_model", "Cancelled", "InputError", "OutputError", "ReconstructionError",
    "RESULT_FORMAT",
    "CablePath", "Crossing", "Result", "StrandRef", "read_result", "write_result",
    "GroundTruth", "TrueCrossing", "read_ground_truth", "write_ground_truth", *_LAZY,
]


def __getattr__(name):
    if name in _LAZY:
        from importlib import import_module

        return getattr(import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
