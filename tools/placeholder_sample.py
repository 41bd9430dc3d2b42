"""Write samples/cable_result.json: a small hand-made result for `make demo` and the tests.

A 4 mm cable lying on a table in three loops (a prolate cycloid), lifted where it passes over
itself, with 24 cameras on an orbit. It stands in until the rendered sample of the ground-truth
issue exists; the curve is analytic, so the file is reproducible:

    python tools/placeholder_sample.py [--overwrite]
"""

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from engine import Camera, CablePath, Crossing, Result, StrandRef, write_result  # noqa: E402

RADIUS = 0.004


def centreline(samples=600):
    """Three loops of a prolate cycloid on the table, z = radius, lifted over its crossings."""
    s = np.linspace(0.0, 3 * 2 * np.pi + np.pi, samples)
    x = 0.035 * s - 0.08 * np.sin(s)
    y = -0.08 * np.cos(s)
    points = np.column_stack([x - x.mean(), y, np.full_like(s, RADIUS)])
    crossings = []
    for loop in range(3):  # each loop crosses itself once, where the two x branches meet y
        ab = [(i, j) for i in range(samples) for j in range(i + 20, samples)
              if 2 * np.pi * loop < s[i] < 2 * np.pi * (loop + 1) + np.pi
              and 2 * np.pi * loop < s[j] < 2 * np.pi * (loop + 1) + np.pi]
        i, j = min(ab, key=lambda ij: np.linalg.norm(points[ij[0], :2] - points[ij[1], :2]))
        over, under = (i, j) if loop % 2 == 0 else (j, i)
        bump = np.exp(-0.5 * ((s - s[over]) / 0.25) ** 2)
        points[:, 2] += 2.2 * RADIUS * bump
        crossings.append((over, under))
    return points, crossings


def orbit_cameras(count=24, width=960, height=720, distance=0.55, elevation_deg=55.0):
    """Pinhole cameras on a circle, all looking at the origin, +z up."""
    cameras = []
    f = 1.1 * width
    for k in range(count):
        azimuth = 2 * np.pi * k / count
        elevation = np.radians(elevation_deg)
        center = distance * np.array([np.cos(azimuth) * np.cos(elevation),
                                      np.sin(azimuth) * np.cos(elevation), np.sin(elevation)])
        forward = -center / np.linalg.norm(center)
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        R = np.stack([right, down, forward])
        cameras.append(Camera(name=f"{k:03d}.jpg", width=width, height=height, model="PINHOLE",
                              params=[f, f, width / 2, height / 2], R=R, t=-R @ center))
    return cameras


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--overwrite", action="store_true")
    args = parser.parse_args()
    points, pairs = centreline()
    crossings = [Crossing(position=(points[o] + points[u]) / 2, over=StrandRef(0, o),
                          under=StrandRef(0, u), confidence=1.0) for o, u in pairs]
    result = Result(radius=RADIUS, paths=(CablePath(np.round(points, 6)),),
                    crossings=tuple(crossings), cameras=tuple(orbit_cameras()), units="m")
    print(write_result(result, ROOT / "samples" / "cable_result.json", overwrite=args.overwrite))


if __name__ == "__main__":
    main()
