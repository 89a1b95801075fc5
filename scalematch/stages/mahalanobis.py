"""Stage 4: the covariance Lambda, loaded, and whitening for the Mahalanobis distance (ALGORITHM.md step 4).

``d(V, V') = sqrt((V - V')^T Lambda^-1 (V - V'))`` equals the Euclidean distance between
``W V`` and ``W V'`` with ``W = Lambda^-1/2`` (whitening), so whitened descriptors go through
ordinary nearest-neighbour search.

Lambda is the covariance of the difference between the descriptors of the *same physical point*
seen in two images. Schmid & Mohr estimated it by tracking points through image sequences; here
it is estimated by tracking points through known synthetic changes of real photos (rotation, a
small scale error, noise, gain and offset): :func:`scalematch.lab.covariance.estimate_covariance`.
The shipped estimate is ``data/jet_covariance.json`` (how it was made is recorded inside it);
``scalematch lab covariance`` re-estimates it from a user's own photos.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from .descriptors import JET_DIM

#: The shipped estimate, at the top of the source tree.
DEFAULT_COVARIANCE = Path(__file__).resolve().parents[2] / "data" / "jet_covariance.json"


@dataclass(frozen=True)
class Covariance:
    matrix: np.ndarray = field(repr=False)  #: (D, D) Lambda
    mean: np.ndarray = field(repr=False)  #: (D,) mean difference (should be ~0)
    samples: int = 0
    provenance: dict = field(default_factory=dict, repr=False)

    def whitening(self) -> np.ndarray:
        """W = Lambda^-1/2 (symmetric), so that |W (V - V')| is the Mahalanobis distance."""
        w, v = np.linalg.eigh(self.matrix)
        w = np.maximum(w, 1e-12 * max(w.max(), 1e-12))
        return (v / np.sqrt(w)) @ v.T


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


def load_covariance(path: Optional[Path] = None) -> Covariance:
    """Read a covariance written by :func:`save_covariance` (default: the shipped one)."""
    p = Path(path) if path is not None else DEFAULT_COVARIANCE
    if not p.is_file():
        raise FileNotFoundError(
            f"{p}: jet covariance not found; re-estimate it with `scalematch covariance` "
            "or pass its path")
    data = json.loads(p.read_text())
    m = np.asarray(data["matrix"], np.float64)
    if m.shape != (JET_DIM, JET_DIM):
        raise ValueError(f"{p}: covariance is {m.shape}, expected {JET_DIM}x{JET_DIM}")
    return Covariance(matrix=m, mean=np.asarray(data.get("mean", np.zeros(JET_DIM))),
                      samples=int(data.get("samples", 0)), provenance=data.get("provenance", {}))
