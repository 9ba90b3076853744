"""Compare the figures of two folders pixel by pixel (PNG images and every GIF frame).

    python benchmarks/compare_images.py DIR_A DIR_B

For each image in both folders: its size, how many pixels differ and the largest difference
(0-255 per channel), and for GIFs the frame count and the differences frame by frame.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from PIL import Image


def frames(path: Path) -> list[NDArray[np.uint8]]:
    """The RGB pixels of every frame (one for a PNG), as a viewer shows them."""
    with Image.open(path) as image:
        out = []
        for index in range(getattr(image, "n_frames", 1)):
            image.seek(index)
            out.append(np.asarray(image.convert("RGB")))
        return out


def compare(a: Path, b: Path) -> bool:
    """Print the differences of each image of ``a`` found in ``b``; True if all are equal."""
    same = True
    for path in sorted([*a.glob("*.png"), *a.glob("*.gif")]):
        other = b / path.name
        if not other.is_file():
            print(f"{path.name}: missing in {b}")
            same = False
            continue
        x, y = frames(path), frames(other)
        if len(x) != len(y) or any(f.shape != g.shape for f, g in zip(x, y, strict=False)):
            print(f"{path.name}: {len(x)} vs {len(y)} frames, {x[0].shape} vs {y[0].shape}")
            same = False
            continue
        diffs = [np.abs(f.astype(int) - g.astype(int)) for f, g in zip(x, y, strict=True)]
        changed = sum(int(np.any(d > 0, axis=2).sum()) for d in diffs)
        worst = max(int(d.max()) for d in diffs)
        same &= changed == 0
        print(f"{path.name}: {len(x)} frame(s) {x[0].shape[1]}x{x[0].shape[0]}, "
              f"{changed} pixels differ, largest difference {worst}, "
              f"sizes {path.stat().st_size} / {other.stat().st_size} bytes")
    return same


if __name__ == "__main__":
    sys.exit(0 if compare(Path(sys.argv[1]), Path(sys.argv[2])) else 1)
