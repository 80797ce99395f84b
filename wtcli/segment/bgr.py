"""The photo as the segmenter and the edge refiner both take it: BGR uint8 [H, W, 3]."""

from __future__ import annotations

import cv2
import numpy as np

from wtcli.errors import InputError


def as_bgr(image: np.ndarray) -> np.ndarray:
    """A uint8 photo as BGR [H, W, 3]: grey and BGRA converted, anything else refused."""
    img = np.asarray(image)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.ndim != 3 or img.shape[2] not in (3, 4) or img.dtype != np.uint8:
        raise InputError(f"expected a BGR uint8 image [H, W, 3], got {img.dtype} {img.shape}")
    if img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img
