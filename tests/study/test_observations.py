"""An advice's observation as stored: an image as the learner saw it; a vector exactly, in
a PNG of what people saw (the rendered frame, or the numbers written out)."""

from __future__ import annotations

import numpy as np

from learner.records import observation_hash
from study.services.observations import decode_png, encode_observation, observation_of


def test_an_image_is_stored_as_the_learner_saw_it() -> None:
    image = np.random.default_rng(1).integers(0, 256, (16, 24, 3), dtype=np.uint8)
    stored = encode_observation(image, lambda: np.zeros((8, 8, 3), np.uint8))
    assert np.array_equal(observation_of(stored), image)
    assert np.array_equal(decode_png(stored), image)


def test_a_vector_is_stored_exactly_with_the_frame_people_saw() -> None:
    vector = np.array([0.1, -2.5e-7, 3.0, np.float32(1) / 3], np.float32)
    frame = np.random.default_rng(2).integers(0, 256, (40, 60, 3), dtype=np.uint8)
    stored = encode_observation(vector, lambda: frame)
    back = observation_of(stored)
    assert back.dtype == np.float32 and np.array_equal(back, vector)
    assert observation_hash(back) == observation_hash(vector)
    assert np.array_equal(decode_png(stored), frame)
    from_doubles = observation_of(encode_observation(vector.astype(np.float64), None))
    assert np.array_equal(from_doubles, vector)  # the learner's float32s


def test_a_vector_without_a_frame_is_shown_as_its_numbers() -> None:
    stored = encode_observation(np.array([1.0, 2.0], np.float32), None)
    picture = decode_png(stored)
    assert picture.shape[2] == 3 and (picture < 128).any() and (picture > 128).any()
    assert observation_of(stored).tolist() == [1.0, 2.0]


def test_a_vectors_hash_reads_its_floats() -> None:
    near = np.array([0.1, 0.2], np.float32), np.array([0.4, 0.3], np.float32)
    assert observation_hash(near[0]) != observation_hash(near[1])  # both 0 as bytes
