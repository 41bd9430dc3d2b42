"""Write a scene folder's preview.jpg: three views, and the first with its exact mask over it.

    python tools/sample_preview.py [samples/sequence]
"""

import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def write_preview(folder, width=960):
    """Tile views 0, 1/3 and 2/3 of the way round and the first view's mask overlay."""
    folder = Path(folder)
    images = sorted((folder / "images").iterdir())
    picks = [images[0], images[len(images) // 3], images[2 * len(images) // 3]]
    tiles = [cv2.imread(str(path)) for path in picks]
    mask = cv2.imread(str(folder / "masks" / (picks[0].stem + ".png")), cv2.IMREAD_GRAYSCALE) > 0
    overlay = tiles[0].copy()
    overlay[mask] = (0.4 * overlay[mask] + np.array([0, 150, 0])).astype(np.uint8)
    half = (width // 2, width // 2 * tiles[0].shape[0] // tiles[0].shape[1])
    small = [cv2.resize(tile, half, interpolation=cv2.INTER_AREA)
             for tile in (tiles[0], overlay, tiles[1], tiles[2])]
    grid = np.vstack([np.hstack(small[:2]), np.hstack(small[2:])])
    path = folder / "preview.jpg"
    cv2.imwrite(str(path), grid, [cv2.IMWRITE_JPEG_QUALITY, 85])
    return path


if __name__ == "__main__":
    print(write_preview(sys.argv[1] if len(sys.argv) > 1 else ROOT / "samples" / "sequence"))
