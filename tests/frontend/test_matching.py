"""Tests of evio_lib.frontend.matching against brute-force definitions."""
import numpy as np
import pytest

from evio_lib.frontend.matching import match_mutual_ratio


def _brute_force(d_all, ratio, allowed):
    """Mutual nearest neighbours among allowed pairs; ratio against the second nearest detection anywhere."""
    d = np.where(allowed, d_all, np.inf)
    out = []
    for i in range(d.shape[0]):
        j = int(np.argmin(d[i]))
        if not np.isfinite(d[i, j]) or int(np.argmin(d[:, j])) != i:
            continue
        others = np.delete(d_all[i], j)
        if ratio is not None and others.size and not d[i, j] < ratio * others.min():
            continue
        out.append([i, j])
    return out


@pytest.mark.parametrize("ratio", [None, 0.8, 0.95])
def test_equals_the_definition_on_random_descriptors(ratio):
    rng = np.random.default_rng(0)
    a = rng.normal(size=(40, 16))
    b = np.concatenate([a[:25] + rng.normal(0, 0.2, (25, 16)), rng.normal(size=(15, 16))])
    allowed = rng.random((40, 40)) < 0.7
    allowed[np.arange(25), np.arange(25)] = True
    d = np.linalg.norm(a[:, None] - b[None], axis=2)
    got = match_mutual_ratio(a, b, ratio=ratio, allowed=allowed)
    assert got.tolist() == _brute_force(d, ratio, allowed)
    assert got.dtype == np.int64


def test_the_ratio_test_looks_beyond_the_window():
    prev = np.array([[1.0, 0.0]])
    curr = np.array([[0.9, 0.1], [0.91, 0.09], [0.0, 1.0]])  # two near-copies of feature 0
    alone = np.array([[True, False, True]])  # only one copy in the window
    assert match_mutual_ratio(prev, curr, allowed=alone).shape == (0, 2)  # still ambiguous
    assert match_mutual_ratio(prev, curr, allowed=alone, ratio=None).tolist() == [[0, 0]]


def test_true_pairs_survive_and_the_distance_gate_applies():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(30, 32)).astype(np.float32)
    b = a[::-1] + rng.normal(0, 0.05, a.shape).astype(np.float32)  # descriptor i is row 29 - i of b
    pairs = match_mutual_ratio(a, b)
    assert pairs.tolist() == [[i, 29 - i] for i in range(30)]
    assert match_mutual_ratio(a, b, max_distance=1e-3).shape == (0, 2)


def test_binary_descriptors_use_hamming_bits():
    a = np.array([[0b11110000], [0b00001111]], np.uint8)
    b = np.array([[0b00001110], [0b11110001]], np.uint8)
    assert match_mutual_ratio(a, b, binary=True).tolist() == [[0, 1], [1, 0]]
    assert match_mutual_ratio(a, b, binary=True, max_distance=0).shape == (0, 2)  # each pair is 1 bit apart


def test_empty_inputs_and_bad_arguments():
    assert match_mutual_ratio(np.zeros((0, 4)), np.ones((3, 4))).shape == (0, 2)
    assert match_mutual_ratio(np.ones((3, 4)), np.zeros((0, 4))).shape == (0, 2)
    with pytest.raises(ValueError, match="ratio"):
        match_mutual_ratio(np.ones((1, 4)), np.ones((1, 4)), ratio=1.5)
    with pytest.raises(ValueError, match="max_distance"):
        match_mutual_ratio(np.ones((1, 4)), np.ones((1, 4)), max_distance=-1.0)
    with pytest.raises(ValueError, match="allowed"):
        match_mutual_ratio(np.ones((2, 4)), np.ones((3, 4)), allowed=np.ones((3, 2), bool))
