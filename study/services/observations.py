"""The learner's observation as stored with advice and shown by reruns: a PNG, lossless, so
the image a person saw is the array the learner saw (`learner.records.observation_hash`)."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image


def encode_png(obs: np.ndarray) -> bytes:
    """The observation exactly as the learner sees it (PNG is lossless)."""
    buffer = io.BytesIO()
    Image.fromarray(np.asarray(obs, dtype=np.uint8)).save(buffer, format="PNG", compress_level=1)
    return buffer.getvalue()


def decode_png(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))
