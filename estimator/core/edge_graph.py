"""The edges between neighbouring faces as a signed incidence matrix, with its weighted graph
Laplacian refilled in place: the edge fit's Retinex prior (:mod:`estimator.light.edge_fit`)
and the footprints' total variation (:mod:`estimator.pipeline.footprints`) both weigh
differences across edges and reweigh them at every step."""
from __future__ import annotations

import threading

import numpy as np
from scipy import sparse

# the graphs built last, by their edges: the fits of one solve run over the same edges many
# times (the sun search fits once per trial direction, each fit of a hypothesis on the faces
# whose radiance is usable), and building the sparsity pattern (a sort of F + 2E keys) costs
# a few times one Gauss-Newton step of a small light. At most _RECENT_SIZE graphs and
# _RECENT_BYTES in all are kept (a graph of a million faces is about 32 MiB), the oldest
# dropped first.
_RECENT: dict[tuple, "EdgeGraph"] = {}
_RECENT_SIZE = 4
_RECENT_BYTES = 64 * 2 ** 20
_RECENT_LOCK = threading.Lock()


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
        # where every entry has one contribution (no face pair listed twice, no edge from a face
        # to itself), each entry is written in place: its face's diagonal, or its edge's -w
        self._distinct = len(keys) == faces + 2 * len(i)

    @classmethod
    def of(cls, i: np.ndarray, j: np.ndarray, faces: int) -> "EdgeGraph":
        """The graph of the edges (i, j) (E',) of F ``faces``, built once for the last few
        distinct edge sets and shared: it holds copies of ``i`` and ``j``, and neither it nor
        the matrices of :meth:`laplacian` (whose index arrays are its pattern's) may be changed
        in place."""
        i, j = np.array(i, dtype=np.int64), np.array(j, dtype=np.int64)   # copies: the caller's may change
        key = (faces, i.tobytes(), j.tobytes())
        with _RECENT_LOCK:
            graph = _RECENT.get(key)
        if graph is None:
            graph = cls(i, j, faces)
            if graph.nbytes <= _RECENT_BYTES:   # one larger alone is built each time
                with _RECENT_LOCK:
                    _RECENT[key] = graph
                    while len(_RECENT) > _RECENT_SIZE or sum(g.nbytes for g in _RECENT.values()) > _RECENT_BYTES:
                        del _RECENT[next(iter(_RECENT))]   # the oldest
        return graph

    @property
    def nbytes(self) -> int:
        """Bytes of the graph's arrays (its edges twice: they also key :meth:`of`'s cache)."""
        p = self._pattern
        return (2 * (self.i.nbytes + self.j.nbytes) + self._slot.nbytes + self._pattern_rows.nbytes
                + p.data.nbytes + p.indices.nbytes + p.indptr.nbytes)

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
        if not self._distinct:
            data = np.bincount(self._slot, np.concatenate([degree, -w, -w]), self._pattern.nnz)
            if scale is not None:
                data *= scale[self._pattern_rows] * scale[self._pattern.indices]
        else:   # the same values written per face and per edge: half the gathers of the above
            faces, edges = self.faces, len(self.i)
            off = -w if scale is None else -w * (scale[self.i] * scale[self.j])
            data = np.empty(self._pattern.nnz)
            data[self._slot[:faces]] = degree if scale is None else degree * (scale * scale)
            data[self._slot[faces:faces + edges]] = off
            data[self._slot[faces + edges:]] = off
        return sparse.csr_matrix((data, self._pattern.indices, self._pattern.indptr), shape=self._pattern.shape)
