"""The reconstruction result and its JSON file (``"format": "cable_recon.result/1"``).

The format is a contract (other tools read it; README, *The engine*): every length is in the
cameras' world units (``units`` is ``"m"`` once the result was scaled to metres, ``"model"``
otherwise).
"""

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..geometry.arrays import read_only
from ..geometry.camera import Camera
from .files import write_atomic

__all__ = [
    "RESULT_FORMAT", "CablePath", "StrandRef", "Crossing", "Result",
    "read_result", "write_result", "result_from_dict",
]

RESULT_FORMAT = "cable_recon.result/1"
UNITS = ("m", "model")


class ResultFormatError(InputError):
    """A result file that does not follow ``cable_recon.result/1``."""


def _points_array(value, where):
    try:
        points = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ResultFormatError(f"{where} must be a list of [x, y, z] numbers") from None
    if points.ndim != 2 or points.shape[1] != 3:
        raise ResultFormatError(f"{where} must be a list of [x, y, z] numbers")
    if not np.all(np.isfinite(points)):
        raise ResultFormatError(f"{where} holds a value that is not a finite number")
    return points


def _srgb(colour):
    """A colour as three floats in [0, 1]; ValueError otherwise."""
    colour = tuple(float(c) for c in colour)
    if len(colour) != 3 or not all(0.0 <= c <= 1.0 for c in colour):
        raise ValueError("colour must be three numbers in [0, 1] (sRGB)")
    return colour


@dataclass(frozen=True, eq=False)
class CablePath:
    """One continuous cable: its centreline in order.

    Attributes
    ----------
    points : ndarray, shape (N, 3)
        Centreline samples in order along the cable, N >= 2.
    radii : ndarray, shape (N,) or None
        Radius at each sample, when it varies along the cable.
    closed : bool
        The last point joins the first.
    colour : tuple of float or None
        This cable's colour as seen in the frames (sRGB, 0 to 1), when a result holds several
        cables; an optional field of the format (``"colour": [r, g, b]`` in the path).
    """

    points: np.ndarray
    radii: np.ndarray = None
    closed: bool = False
    colour: tuple = None

    def __post_init__(self):
        points = _points_array(self.points, "points")
        if len(points) < 2:
            raise ValueError("a cable path needs at least 2 points")
        object.__setattr__(self, "points", read_only(points))
        if self.radii is not None:
            radii = np.asarray(self.radii, dtype=np.float64).reshape(-1)
            if radii.shape != (len(points),):
                raise ValueError(f"radii must have one value per point ({len(points)})")
            if not np.all(np.isfinite(radii) & (radii > 0)):
                raise ValueError("radii must be positive finite numbers")
            object.__setattr__(self, "radii", read_only(radii))
        object.__setattr__(self, "closed", bool(self.closed))
        if self.colour is not None:
            object.__setattr__(self, "colour", _srgb(self.colour))

    @property
    def length(self):
        """Length of the centreline polyline (including the closing edge of a loop)."""
        points = np.vstack([self.points, self.points[:1]]) if self.closed else self.points
        return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


@dataclass(frozen=True)
class StrandRef:
    """A sample on a path: ``paths[path].points[index]``."""

    path: int
    index: int


@dataclass(frozen=True, eq=False)
class Crossing:
    """Where the cable passes over itself (or another cable).

    Attributes
    ----------
    position : ndarray, shape (3,)
        The crossing's location.
    over, under : StrandRef
        The samples of the upper and the lower strand at the crossing.
    confidence : float
        How sure the over/under decision is, from 0 (a guess) to 1.
    """

    position: np.ndarray
    over: StrandRef
    under: StrandRef
    confidence: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "position", read_only(np.asarray(self.position).reshape(3)))
        if not 0.0 <= float(self.confidence) <= 1.0:
            raise ValueError("crossing confidence must lie in [0, 1]")
        object.__setattr__(self, "confidence", float(self.confidence))

    def flipped(self):
        """The same crossing with over and under swapped."""
        return Crossing(self.position, self.under, self.over, self.confidence)


@dataclass(frozen=True, eq=False)
class Result:
    """What a reconstruction produces: the cable path(s), crossings and cameras.

    Attributes
    ----------
    radius : float
        Cable radius in ``units``.
    paths : tuple of CablePath
        One per cable.
    crossings : tuple of Crossing
    cameras : tuple of Camera
    units : str
        ``"m"`` or ``"model"``.
    warnings : tuple of str
    timings : dict
        Seconds per stage.
    colour : tuple of float or None
        The cable's colour as seen in the frames (sRGB, 0 to 1), when known; an optional
        field of the format (``"colour": [r, g, b]``).
    run : dict or None
        How the run was made, when known: ``{"settings": {...}, "inputs": {...}}``, every
        stage's settings (``settings_to_dict`` of a ``PipelineSettings``) and the colour and
        scale it was given (``hsv``, ``diameter``, ``length``); an optional field of the format
        (``"run"``), which ``python -m engine reconstruct --settings`` reads back.
    """

    radius: float
    paths: tuple
    crossings: tuple = ()
    cameras: tuple = ()
    units: str = "model"
    warnings: tuple = ()
    timings: dict = field(default_factory=dict)
    colour: tuple = None
    run: dict = None

    def __post_init__(self):
        if not (isinstance(self.radius, (int, float)) and math.isfinite(self.radius)
                and self.radius > 0):
            raise ValueError("radius must be a positive finite number")
        if self.units not in UNITS:
            raise ValueError(f"units must be one of {UNITS}, not {self.units!r}")
        object.__setattr__(self, "radius", float(self.radius))
        for name in ("paths", "crossings", "cameras", "warnings"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        if not self.paths:
            raise ValueError("a result needs at least one path")
        if self.colour is not None:
            object.__setattr__(self, "colour", _srgb(self.colour))
        for k, crossing in enumerate(self.crossings):
            for role in ("over", "under"):
                ref = getattr(crossing, role)
                if not (0 <= ref.path < len(self.paths)
                        and 0 <= ref.index < len(self.paths[ref.path].points)):
                    raise ValueError(
                        f"crossings[{k}].{role} points at path {ref.path} index {ref.index}, "
                        "which does not exist")

    def to_dict(self):
        """The result as a JSON-ready dict in ``cable_recon.result/1``."""
        paths = []
        for path in self.paths:
            entry = {"points": path.points.tolist()}
            if path.radii is not None:
                entry["radii"] = path.radii.tolist()
            entry["closed"] = path.closed
            if path.colour is not None:
                entry["colour"] = list(path.colour)
            paths.append(entry)
        document = {
            "format": RESULT_FORMAT,
            "units": self.units,
            "radius": self.radius,
            "paths": paths,
            "crossings": [
                {"position": c.position.tolist(),
                 "over": {"path": c.over.path, "index": c.over.index},
                 "under": {"path": c.under.path, "index": c.under.index},
                 "confidence": c.confidence}
                for c in self.crossings
            ],
            "cameras": [camera.to_dict() for camera in self.cameras],
            "warnings": list(self.warnings),
            "timings": {str(k): float(v) for k, v in self.timings.items()},
        }
        if self.colour is not None:
            document["colour"] = list(self.colour)
        if self.run is not None:
            document["run"] = self.run
        return document


def _colour_field(colour, where):
    """An optional ``[r, g, b]`` field (numbers in [0, 1]), or :class:`ResultFormatError`."""
    if colour is not None and not (
            isinstance(colour, list) and len(colour) == 3
            and all(isinstance(c, (int, float)) and not isinstance(c, bool) and 0 <= c <= 1
                    for c in colour)):
        raise ResultFormatError(f"{where} must be [r, g, b] with numbers in [0, 1]")
    return colour


def _require(data, key, kind, where):
    if key not in data:
        raise ResultFormatError(f"{where} is missing {key!r}")
    value = data[key]
    if kind is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    elif kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    else:
        ok = isinstance(value, kind)
    if not ok:
        kind_name = {float: "a number", int: "an integer", list: "a list", dict: "an object",
                     str: "a string", bool: "true or false"}[kind]
        raise ResultFormatError(f"{where}.{key} must be {kind_name}")
    return value


def _strand(data, where):
    if not isinstance(data, dict):
        raise ResultFormatError(f"{where} must be an object with 'path' and 'index'")
    return StrandRef(_require(data, "path", int, where), _require(data, "index", int, where))


def result_from_dict(data):
    """Validate a parsed ``cable_recon.result/1`` document and build a :class:`Result`.

    Raises
    ------
    InputError
        The document does not follow the format; the message names the offending field.
    """
    if not isinstance(data, dict):
        raise ResultFormatError("the file must hold a JSON object")
    fmt = data.get("format")
    if fmt != RESULT_FORMAT:
        raise ResultFormatError(f"'format' must be {RESULT_FORMAT!r}, found {fmt!r}")
    units = _require(data, "units", str, "result")
    if units not in UNITS:
        raise ResultFormatError(f"result.units must be 'm' or 'model', found {units!r}")
    radius = _require(data, "radius", float, "result")
    if not (math.isfinite(radius) and radius > 0):
        raise ResultFormatError("result.radius must be a positive number")
    raw_paths = _require(data, "paths", list, "result")
    if not raw_paths:
        raise ResultFormatError("result.paths is empty: a result holds at least one path")
    paths = [_path_from_dict(raw, f"paths[{i}]") for i, raw in enumerate(raw_paths)]
    for key in ("crossings", "cameras"):
        if not isinstance(data.get(key, []), list):
            raise ResultFormatError(f"result.{key} must be a list")
    crossings = [_crossing_from_dict(raw, f"crossings[{k}]")
                 for k, raw in enumerate(data.get("crossings", []))]
    cameras = []
    for k, raw in enumerate(data.get("cameras", [])):
        try:
            cameras.append(Camera.from_dict(raw))
        except InputError as error:
            raise ResultFormatError(f"cameras[{k}]: {error}") from None
    warnings = data.get("warnings", [])
    if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
        raise ResultFormatError("result.warnings must be a list of strings")
    timings = data.get("timings", {})
    if not isinstance(timings, dict) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in timings.values()):
        raise ResultFormatError("result.timings must map stage names to seconds")
    colour = _colour_field(data.get("colour"), "result.colour")
    run = data.get("run")
    if run is not None and not (isinstance(run, dict)
                                and all(isinstance(run.get(key, {}), dict)
                                        for key in ("settings", "inputs"))):
        raise ResultFormatError("result.run must be an object holding 'settings' and "
                                "'inputs' objects")
    try:
        return Result(radius=float(radius), paths=tuple(paths), crossings=tuple(crossings),
                      cameras=tuple(cameras), units=units, warnings=tuple(warnings),
                      timings=dict(timings), colour=colour, run=run)
    except ValueError as error:  # cross-field checks (crossing indices) live in Result
        raise ResultFormatError(str(error)) from None


def _path_from_dict(raw, where):
    """A :class:`CablePath` from the result's ``paths`` entry ``where``, checked."""
    if not isinstance(raw, dict):
        raise ResultFormatError(f"{where} must be an object")
    points = _points_array(_require(raw, "points", list, where), f"{where}.points")
    if len(points) < 2:
        raise ResultFormatError(f"{where}.points needs at least 2 points")
    radii = raw.get("radii")
    if radii is not None:
        try:
            radii = np.asarray(radii, dtype=np.float64)
        except (TypeError, ValueError):
            raise ResultFormatError(f"{where}.radii must be a list of numbers") from None
        if radii.shape != (len(points),) or not np.all(np.isfinite(radii) & (radii > 0)):
            raise ResultFormatError(
                f"{where}.radii must hold one positive number per point ({len(points)})")
    closed = raw.get("closed", False)
    if not isinstance(closed, bool):
        raise ResultFormatError(f"{where}.closed must be true or false")
    return CablePath(points, radii, closed, _colour_field(raw.get("colour"), f"{where}.colour"))


def _crossing_from_dict(raw, where):
    """A :class:`Crossing` from the result's ``crossings`` entry ``where``, checked."""
    if not isinstance(raw, dict):
        raise ResultFormatError(f"{where} must be an object")
    position = _points_array([_require(raw, "position", list, where)], f"{where}.position")[0]
    over = _strand(raw.get("over"), f"{where}.over")
    under = _strand(raw.get("under"), f"{where}.under")
    confidence = raw.get("confidence", 1.0)
    if not isinstance(confidence, (int, float)) or not 0.0 <= confidence <= 1.0:
        raise ResultFormatError(f"{where}.confidence must be a number in [0, 1]")
    return Crossing(position, over, under, confidence)


def read_result(path):
    """Read and validate a result JSON file.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    Result

    Raises
    ------
    InputError
        The file is missing, is not JSON, or does not follow ``cable_recon.result/1``; the
        message starts with the file name.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"{path}: cannot be read ({error})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise InputError(f"{path}: not valid JSON ({error})") from None
    try:
        return result_from_dict(data)
    except InputError as error:
        raise InputError(f"{path}: {error}") from None


def write_result(result, path, *, overwrite=False):
    """Write a result as JSON, atomically and never over an existing file unless asked.

    Parameters
    ----------
    result : Result
    path : str or os.PathLike
    overwrite : bool, optional
        Replace an existing file.

    Returns
    -------
    pathlib.Path
    """
    text = json.dumps(result.to_dict(), indent=1, allow_nan=False)
    return write_atomic(path, text + "\n", overwrite=overwrite)
