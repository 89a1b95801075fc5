"""Stage 4: the covariance Lambda, loaded, and whitening for the Mahalanobis distance (docs/ALGORITHM.md step 4).

``d(V, V') = sqrt((V - V')^T Lambda^-1 (V - V'))`` equals the Euclidean distance between
``W V`` and ``W V'`` with ``W = Lambda^-1/2`` (whitening), so whitened descriptors go through
ordinary nearest-neighbour search.

Lambda is the covariance of the difference between the descriptors of the *same physical point*
seen in two images. Schmid & Mohr estimated it by tracking points through image sequences; here
it is estimated by tracking points through known synthetic changes of real photos (rotation, a
small scale error, noise, gain and offset): :func:`scalematch.lab.covariance.estimate_covariance`.
The shipped estimate is the package data file ``scalematch/data/jet_covariance.json`` (how it
was made is recorded inside it); ``scalematch lab covariance`` re-estimates it from a user's own
photos, and ``Config(covariance_path=...)`` uses that instead. A loaded Lambda and its whitening
are cached per file (keyed by path, modification time and size), so repeated matches read it once.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path
from typing import Optional, Union

import numpy as np

from .descriptors import JET_DIM

#: The shipped estimate: package data, read with importlib.resources (works from a wheel).
PACKAGED_COVARIANCE = "jet_covariance.json"


@dataclass(frozen=True)
class Covariance:
    matrix: np.ndarray = field(repr=False)  #: (D, D) Lambda
    mean: np.ndarray = field(repr=False)  #: (D,) mean difference (should be ~0)
    samples: int = 0
    provenance: dict = field(default_factory=dict, repr=False)
    #: which Lambda this is: "packaged" or the resolved path, then the first 12 hex digits of
    #: the file's SHA-256 (recorded in the result's ``covariance_used``)
    source: str = ""

    def whitening(self) -> np.ndarray:
        """W = Lambda^-1/2 (symmetric, (D, D), read-only), so that |W (V - V')| is the
        Mahalanobis distance. Computed once per Covariance."""
        return self._whitening

    @cached_property
    def _whitening(self) -> np.ndarray:
        w, v = np.linalg.eigh(self.matrix)
        w = np.maximum(w, 1e-12 * max(w.max(), 1e-12))
        return _read_only((v / np.sqrt(w)) @ v.T)


def _read_only(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def whiten(desc: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Descriptors (N, D) -> whitened (N, D) float32."""
    return (np.asarray(desc, np.float64) @ w.T).astype(np.float32)


def mahalanobis(v: np.ndarray, v2: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Direct Mahalanobis distances between rows of v and v2 (for checks)."""
    d = np.asarray(v, np.float64) - np.asarray(v2, np.float64)
    return np.sqrt(np.einsum("ni,ij,nj->n", d, np.linalg.inv(cov), d))


def save_covariance(cov: Covariance, path: Path) -> None:
    data = {"matrix": cov.matrix.tolist(), "mean": cov.mean.tolist(), "samples": cov.samples,
            "dimension": int(cov.matrix.shape[0]), "provenance": cov.provenance}
    Path(path).write_text(json.dumps(data, indent=2) + "\n")


def load_covariance(path: Union[str, Path, None] = None) -> Covariance:
    """Read a covariance written by :func:`save_covariance` (default: the packaged one).

    Cached: the same file (same resolved path, modification time and size) is parsed once per
    process; the arrays of the returned Covariance are read-only, since it is shared.

    >>> cov = load_covariance()
    >>> cov.matrix.shape, cov.source.startswith("packaged sha256:")
    ((7, 7), True)
    """
    if path is None:
        return _load(None, (0, 0))
    p = Path(path).resolve()
    if not p.is_file():
        raise FileNotFoundError(
            f"{p}: jet covariance not found; re-estimate it with `scalematch lab covariance` "
            "or pass its path")
    st = p.stat()
    return _load(str(p), (st.st_mtime_ns, st.st_size))


@lru_cache(maxsize=8)
def _load(path: Optional[str], stamp: tuple) -> Covariance:
    """Parse one covariance file (None: the packaged one); ``stamp`` (modification time, size)
    only keys the cache, so a file rewritten in place is read again."""
    if path is None:
        from importlib import resources  # the paper mode only (10-17 ms of start-up)

        raw = resources.files("scalematch").joinpath("data").joinpath(PACKAGED_COVARIANCE).read_bytes()
        name = "packaged"
    else:
        raw = Path(path).read_bytes()
        name = path
    data = json.loads(raw)
    m = np.asarray(data["matrix"], np.float64)
    if m.shape != (JET_DIM, JET_DIM):
        raise ValueError(f"{name}: covariance is {m.shape}, expected {JET_DIM}x{JET_DIM}")
    return Covariance(matrix=_read_only(m),
                      mean=_read_only(np.asarray(data.get("mean", np.zeros(JET_DIM)), np.float64)),
                      samples=int(data.get("samples", 0)), provenance=data.get("provenance", {}),
                      source=f"{name} sha256:{_sha256(raw)[:12]}")


def _sha256(raw: bytes) -> str:
    import hashlib  # the paper mode only

    return hashlib.sha256(raw).hexdigest()
