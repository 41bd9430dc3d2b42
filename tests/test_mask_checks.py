"""The checks that warn when the masks held more than the cable (`engine/stages/mask_checks.py`)."""

import math
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from conftest import look_at_camera
from engine.io.packed_mask import PackedMask
from engine.stages.mask_checks import (MaskCheckSettings, core_thickness, mask_warnings,
                                       unexplained_share)

RADIUS = 0.005


def test_core_thickness_is_the_volume_over_a_tubes():
    # a tube of radius 1/sqrt(pi) and length 100 holds 100 unit voxels
    assert core_thickness(100, 1.0, 1 / math.sqrt(math.pi), 100.0) == pytest.approx(1.0)
    assert core_thickness(250, 1.0, 1 / math.sqrt(math.pi), 100.0) == pytest.approx(2.5)
    assert core_thickness(800, 0.5, 1 / math.sqrt(math.pi), 100.0) == pytest.approx(1.0)
    assert core_thickness(10, 1.0, 1.0, 0.0) == math.inf


def _view(camera, mask):
    return SimpleNamespace(camera=camera, mask=PackedMask(mask))


def _line_and_mask(camera, *, extra=None):
    """A straight cable on the table and the mask of its projection (plus ``extra``)."""
    line = np.column_stack([np.linspace(-0.1, 0.1, 41), np.zeros(41), np.full(41, RADIUS)])
    pixels, depth = camera.project(line)
    pixel_radius = RADIUS * np.mean(camera.focal) / np.median(depth)
    mask = np.zeros((camera.height, camera.width), np.uint8)
    cv2.polylines(mask, [np.round(pixels - 0.5).astype(np.int32).reshape(-1, 1, 2)], False, 1,
                  max(1, int(round(2 * pixel_radius))))
    if extra is not None:
        mask[extra] = 1
    return line, mask > 0


def test_a_mask_of_the_cable_alone_is_explained():
    cameras = [look_at_camera(f"{k:03d}.png", [0.3 * np.cos(a), 0.3 * np.sin(a), 0.35])
               for k, a in enumerate(np.linspace(0, np.pi, 4))]
    views = []
    for camera in cameras:
        line, mask = _line_and_mask(camera)
        views.append(_view(camera, mask))
    shares = unexplained_share([(line, False)], RADIUS, views)
    assert [name for name, _ in shares] == [c.name for c in cameras]
    assert max(share for _, share in shares) < 0.01
    assert mask_warnings(shares=shares) == []


def test_a_patch_the_curve_does_not_follow_is_counted_and_named():
    camera = look_at_camera("000.png", [0.0, -0.3, 0.35])
    patch = (slice(20, 80), slice(20, 120))  # a corner far from the cable
    line, mask = _line_and_mask(camera, extra=patch)
    (name, share), = unexplained_share([(line, False)], RADIUS, [_view(camera, mask)])
    assert name == "000.png"
    assert share == pytest.approx(60 * 100 / mask.sum(), rel=0.01)
    empty = _view(look_at_camera("001.png", [0.0, 0.3, 0.35]), np.zeros_like(mask))
    assert len(unexplained_share([(line, False)], RADIUS, [empty])) == 0  # no cable pixels
    warning, = mask_warnings(shares=[("000.png", share), ("001.png", 0.0)])
    assert f"{100 * share / 2:.0f}% of the mask pixels" in warning
    assert "000.png" in warning and "python -m engine segment" in warning
    assert mask_warnings(shares=[("000.png", share)],
                         settings=MaskCheckSettings(unexplained=0)) == []


def test_a_thick_core_warns_and_a_tube_does_not():
    settings = MaskCheckSettings()
    assert mask_warnings(thickness=1.6) == []
    warning, = mask_warnings(thickness=2.83)
    assert "2.8 times the volume of a tube" in warning
    assert mask_warnings(thickness=50.0, settings=MaskCheckSettings(core_thickness=0)) == []
    assert 1.57 < settings.core_thickness < 14  # exact masks vs a slab (module notes)
    with pytest.raises(ValueError, match="band"):
        MaskCheckSettings(band=-1.0)


def test_a_core_thinner_than_a_tube_warns():
    settings = MaskCheckSettings()
    assert mask_warnings(thickness=1.13) == []  # the thinnest right run on the tuning looks
    warning, = mask_warnings(thickness=0.83)
    assert "disagree across views" in warning and "0.83 times" in warning
    assert warning.endswith("python -m engine segment`")
    assert mask_warnings(thickness=0.5, settings=MaskCheckSettings(thin_core=0)) == []
    assert 0.97 < settings.thin_core < 1.13  # wrong and right tuning runs (module notes)
    with pytest.raises(ValueError, match="under core_thickness"):
        MaskCheckSettings(thin_core=3.0)
    assert MaskCheckSettings(thin_core=3.0, core_thickness=0).thin_core == 3.0
