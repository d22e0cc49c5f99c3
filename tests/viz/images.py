"""What a written figure must be: a real image with something drawn on it."""

from pathlib import Path

import numpy as np
from PIL import Image


def assert_image(path: Path) -> np.ndarray:
    """Opens ``path`` (PNG or GIF, first frame) and checks it is a non-empty picture of
    more than one colour; returns its RGB pixels."""
    assert path.is_file() and path.stat().st_size > 0, path
    with Image.open(path) as image:
        image.verify()
    with Image.open(path) as image:
        pixels = np.asarray(image.convert("RGB"))
    assert pixels.shape[0] > 0 and pixels.shape[1] > 0, path
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 1, f"{path} is a single colour"
    return pixels
