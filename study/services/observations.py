"""The learner's observation as stored with advice and shown by reruns: a PNG, lossless, so
the image a person saw is the array the learner saw (`learner.records.observation_hash`).

A task whose observations are vectors stores a PNG of what people see of that moment (the
environment's rendered frame; where it renders none, the numbers written out) and the
vector itself, exactly, as JSON in the PNG's text (`VECTOR_KEY`): the image stays one an
advisor, the dashboard and an export can show, and `observation_of` gives back the vector
the learner saw, which replays compare by its hash.
"""

from __future__ import annotations

import io
import json
from collections.abc import Callable
from typing import Any

import numpy as np
from PIL import Image, ImageDraw
from PIL.PngImagePlugin import PngInfo

VECTOR_KEY = "ideeprl-observation"
"""The PNG text key under which a vector observation is stored (a JSON list of numbers)."""


def encode_png(obs: np.ndarray) -> bytes:
    """The observation exactly as the learner sees it (PNG is lossless)."""
    buffer = io.BytesIO()
    Image.fromarray(np.asarray(obs, dtype=np.uint8)).save(buffer, format="PNG", compress_level=1)
    return buffer.getvalue()


def decode_png(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def encode_observation(obs: np.ndarray, frame: Callable[[], Any] | None) -> bytes:
    """An advice's observation: an image as `encode_png` stores it; a vector as the PNG of
    `frame()` (what people see, asked for only here) or of its numbers written out, with the
    vector in its text."""
    array = np.asarray(obs)
    if array.ndim != 1:
        return encode_png(array)
    vector = array.astype(np.float32)
    shown = frame() if frame is not None else None
    picture = _written(vector) if shown is None else Image.fromarray(np.asarray(shown, np.uint8))
    text = PngInfo()
    text.add_text(VECTOR_KEY, json.dumps(vector.tolist()))
    buffer = io.BytesIO()
    picture.save(buffer, format="PNG", compress_level=1, pnginfo=text)
    return buffer.getvalue()


def observation_of(data: bytes) -> np.ndarray:
    """The observation the learner saw, from `encode_observation`'s PNG: the vector (float32)
    where it holds one, else the RGB image."""
    image = Image.open(io.BytesIO(data))
    vector = getattr(image, "text", {}).get(VECTOR_KEY)
    if vector is not None:
        return np.asarray(json.loads(vector), np.float32)
    return np.asarray(image.convert("RGB"))


def _written(vector: np.ndarray) -> Image.Image:
    """A vector's numbers, one a line, for a task that renders no frame."""
    lines = [f"{i}: {v:.4g}" for i, v in enumerate(vector.tolist())]
    picture = Image.new("RGB", (160, 8 + 14 * len(lines)), "white")
    ImageDraw.Draw(picture).multiline_text((6, 4), "\n".join(lines), fill="black", spacing=4)
    return picture
