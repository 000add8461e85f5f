"""The edges between neighbouring faces as a signed incidence matrix, with its weighted graph
Laplacian refilled in place: the edge fit's Retinex prior (:mod:`estimator.light.edge_fit`)
and the footprints' total variation (:mod:`estimator.pipeline.footprints`) both weigh
differences across edges and reweigh them at every step."""
from __future__ import annotations

import numpy as np
from scipy import sparse


class EdgeGraph:
    """The usable edges (i_e, j_e) of F faces as the signed incidence B of the fit: an edge's log
    ratio is (B x)_e = x_i - x_j, and the weighted graph Laplacian B^T W B, whose sparsity is
    fixed, is refilled per weighting without a sparse product (the edge fit forms it at every
    Gauss-Newton step)."""

    def __init__(self, i: np.ndarray, j: np.ndarray, faces: int):
        self.i, self.j, self.faces = i, j, faces
        diagonal = np.arange(faces)
        rows, cols = np.concatenate([diagonal, i, j]), np.concatenate([diagonal, j, i])
        keys, self._slot = np.unique(rows * faces + cols, return_inverse=True)
        self._pattern = sparse.csr_matrix((np.ones(len(keys)), (keys // faces, keys % faces)), shape=(faces, faces))
        self._pattern.sort_indices()
        self._pattern_rows = np.repeat(np.arange(faces), np.diff(self._pattern.indptr))

    def __len__(self) -> int:
        return len(self.i)

    def difference(self, x: np.ndarray) -> np.ndarray:
        """(E',) B x for x (F,)."""
        return x[self.i] - x[self.j]

    def gather(self, v: np.ndarray) -> np.ndarray:
        """(F,) B^T v for v (E',)."""
        return np.bincount(self.i, v, self.faces) - np.bincount(self.j, v, self.faces)

    def laplacian(self, w: np.ndarray, scale: np.ndarray | None = None,
                  diagonal: np.ndarray | None = None) -> sparse.csr_matrix:
        """(F, F) D (B^T diag(w) B + diag(``diagonal``)) D for edge weights w (E',), the
        ``diagonal`` (F,) (None: 0) and D = diag(``scale``) (F,) (None: the identity). The
        scaling is applied to the O(nnz) entries (the edge fit's rows each divided by their
        face's shading) rather than to an (F, k) matrix per step."""
        degree = np.bincount(self.i, w, self.faces) + np.bincount(self.j, w, self.faces)
        if diagonal is not None:
            degree = degree + diagonal
        data = np.bincount(self._slot, np.concatenate([degree, -w, -w]), self._pattern.nnz)
        if scale is not None:
            data *= scale[self._pattern_rows] * scale[self._pattern.indices]
        return sparse.csr_matrix((data, self._pattern.indices, self._pattern.indptr), shape=self._pattern.shape)
