"""The jet covariance Lambda, whitening and the Mahalanobis distance (stages/mahalanobis.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scalematch.stages.descriptors import JET_DIM
from importlib import resources

from scalematch.stages.mahalanobis import (PACKAGED_COVARIANCE, Covariance, load_covariance,
                                           mahalanobis, save_covariance, whiten)


def _random_spd(rng, d=JET_DIM):
    a = rng.normal(size=(d, d))
    return a @ a.T + 0.1 * np.eye(d)


@pytest.mark.parametrize("which", ["random", "shipped"])
def test_whitened_euclidean_distance_is_the_mahalanobis_distance(which):
    rng = np.random.default_rng(0)
    cov = _random_spd(rng) if which == "random" else load_covariance().matrix
    w = Covariance(matrix=cov, mean=np.zeros(JET_DIM)).whitening()
    # W Lambda W^T = I: the defining property (measured 5e-14 on the shipped Lambda)
    np.testing.assert_allclose(w @ cov @ w.T, np.eye(JET_DIM), atol=1e-9)
    np.testing.assert_allclose(w, w.T, atol=1e-12)  # the symmetric square root
    v, v2 = rng.normal(size=(200, JET_DIM)), rng.normal(size=(200, JET_DIM))
    euclid = np.linalg.norm(whiten(v, w).astype(np.float64) - whiten(v2, w), axis=1)
    # whiten returns float32: measured relative error <= 9e-8 on both matrices
    np.testing.assert_allclose(euclid, mahalanobis(v, v2, cov), rtol=1e-6)


def test_mahalanobis_of_a_diagonal_covariance_by_hand():
    cov = np.diag([4.0, 1.0, 0.25, 1, 1, 1, 1])
    v = np.zeros((1, JET_DIM))
    v2 = np.array([[2.0, 1.0, 0.5, 0, 0, 0, 0]])  # each component one std: d = sqrt(3)
    np.testing.assert_allclose(mahalanobis(v, v2, cov), [np.sqrt(3.0)], rtol=1e-12)


def test_shipped_covariance_is_symmetric_positive_definite_of_the_jet_dimension():
    cov = load_covariance()
    # package data (importlib.resources), so a plain `pip install .` ships it
    assert resources.files("scalematch").joinpath("data").joinpath(PACKAGED_COVARIANCE).is_file()
    assert cov.source.startswith("packaged sha256:") and len(cov.source.split(":")[1]) == 12
    assert cov.matrix.shape == (JET_DIM, JET_DIM) == (7, 7)
    np.testing.assert_allclose(cov.matrix, cov.matrix.T, atol=1e-12)
    eig = np.linalg.eigvalsh(cov.matrix)
    assert eig.min() > 0  # measured smallest eigenvalue 0.0091, largest 8.9
    assert cov.samples > 1000  # measured 74108 tracked differences
    assert cov.mean.shape == (JET_DIM,)
    # the mean difference of the same point seen twice is ~0: under 0.1 std per invariant
    assert np.all(np.abs(cov.mean) < 0.1 * np.sqrt(np.diag(cov.matrix)))
    for key in ("method", "seed", "recipe", "photos"):
        assert key in cov.provenance


def test_save_then_load_gives_the_same_covariance(tmp_path):
    rng = np.random.default_rng(1)
    cov = Covariance(matrix=_random_spd(rng), mean=rng.normal(size=JET_DIM), samples=123,
                     provenance={"method": "test"})
    save_covariance(cov, tmp_path / "c.json")
    back = load_covariance(tmp_path / "c.json")
    np.testing.assert_array_equal(back.matrix, cov.matrix)
    np.testing.assert_array_equal(back.mean, cov.mean)
    assert back.samples == 123 and back.provenance == {"method": "test"}


def test_a_missing_file_raises_a_clear_error(tmp_path):
    path = tmp_path / "nowhere.json"
    with pytest.raises(FileNotFoundError, match="scalematch lab covariance") as err:
        load_covariance(path)
    assert "nowhere.json" in str(err.value)


def test_a_matrix_of_the_wrong_size_is_a_value_error(tmp_path):
    path = tmp_path / "small.json"
    path.write_text(json.dumps({"matrix": np.eye(3).tolist()}))
    with pytest.raises(ValueError, match="expected 7x7"):
        load_covariance(path)


def test_a_loaded_covariance_is_cached_read_only_and_reread_when_the_file_changes(tmp_path):
    assert load_covariance() is load_covariance()
    shipped = load_covariance()
    assert shipped.whitening() is shipped.whitening()  # decomposed once
    for a in (shipped.matrix, shipped.mean, shipped.whitening()):
        with pytest.raises(ValueError, match="read-only"):
            a[0] = 0.0
    path = tmp_path / "c.json"
    save_covariance(Covariance(matrix=np.eye(JET_DIM), mean=np.zeros(JET_DIM)), path)
    first = load_covariance(path)
    assert load_covariance(str(path)) is first
    assert first.source.startswith(str(path.resolve()) + " sha256:")
    save_covariance(Covariance(matrix=2 * np.eye(JET_DIM), mean=np.zeros(JET_DIM), samples=5),
                    path)
    again = load_covariance(path)
    assert again.samples == 5 and again.source != first.source
