"""Cable Reconstruction engine: images of a cable to one continuous 3D centreline.

Pure NumPy / SciPy / OpenCV / pycolmap / networkx; it never imports Blender, so it runs from
the command line (``python -m engine``), in a pipeline, or inside the Blender extension.
"""

from .errors import Cancelled, InputError, OutputError, ReconstructionError
from .geometry.camera import CAMERA_MODELS, Camera
from .io.colmap import ColmapModel, read_colmap_model, write_colmap_model
from .io.ground_truth import GroundTruth, TrueCrossing, read_ground_truth, write_ground_truth
from .io.result import (RESULT_FORMAT, CablePath, Crossing, Result, StrandRef, read_result,
                        write_result)

__version__ = "0.1.0"

#: Stage APIs, imported on first use (scipy, OpenCV and pycolmap are not needed to read a
#: result): name -> module. The metrics against a ground truth are developer code, in
#: ``engine.evaluation`` (not in the extension).
_LAZY = {
    "SegmentationSettings": "stages.segmentation", "segment_frame": "stages.segmentation",
    "auto_colour": "stages.segmentation", "ColourRange": "stages.segmentation",
    "CameraEstimationSettings": "stages.cameras", "estimate_cameras": "stages.cameras",
    "MaskAgreementSettings": "stages.mask_agreement", "agree_masks": "stages.mask_agreement",
    "CarvingSettings": "stages.carving", "VoxelGrid": "stages.carving", "carve": "stages.carving",
    "SegmentGraphSettings": "stages.segment_graph", "SegmentGraph": "stages.segment_graph",
    "extract_segment_graph": "stages.segment_graph",
    "extract_segment_graph_from_voxels": "stages.segment_graph",
    "RodSettings": "stages.rod", "Rod": "stages.rod", "solve_rod": "stages.rod",
    "RodFitSettings": "stages.rod_fit", "RodFit": "stages.rod_fit", "fit_rod": "stages.rod_fit",
    "ImageEvidence": "stages.rod_fit", "Contact": "stages.rod_fit", "Voxels": "stages.rod_fit",
    "TopologySettings": "stages.topology", "resolve_topology": "stages.topology",
    "PipelineSettings": "pipeline", "Reconstruction": "pipeline", "reconstruct": "pipeline",
    "run_reconstruction": "pipeline", "RunInputs": "pipeline", "read_run": "pipeline",
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
