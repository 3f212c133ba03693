"""Sparse normal equations of a linearised graph and their LDLᵀ factorisation (compiled).

The batch solver's linear system ``min ‖A δ − b‖²`` is assembled as ``H δ = g`` with
``H = AᵀA`` and ``g = Aᵀb``, straight from the numpy linearisation's blocks (no per-factor
Python object), and solved by a sparse ``LDLᵀ`` factorisation in a fill-reducing order:

* **Structure, once per solve** (:class:`NormalEquations`): the factors of a solve do not
  change between its iterations, so the pattern of ``H`` (upper triangle, compressed columns,
  variables permuted into elimination order) and the place of every block entry in it are
  computed once, as are the elimination tree and the column counts of ``L`` (symbolic
  analysis).  The ordering is GTSAM's COLAMD (or METIS) on the variables' adjacency, the same
  ordering method as GTSAM's own elimination.
* **Values, every iteration**: the block products ``A_aᵀA_a``, ``A_aᵀA_b``, ``A_bᵀA_b`` and
  ``A_aᵀb``, ``A_bᵀb`` of every factor are added into place by compiled loops; ``L`` and ``D``
  come from an up-looking ``LDLᵀ`` (the algorithm of QDLDL: each row of ``L`` by a sparse
  triangular solve along the elimination tree) compiled with numba; Levenberg-Marquardt damping
  adds to the diagonal of the same pattern.
* **Singular systems**: a pivot of ``D`` that is not positive (zero, negative or NaN: a
  variable the factors do not determine, e.g. a pose without odometry seeing one line, or
  rounding in a badly conditioned system) raises
  :class:`~slam.errors.EstimationError` naming the variable (``describe``), as GTSAM's
  elimination stops with an indeterminant system on a non-positive pivot.

Why beside GTSAM's elimination: for the planar problems here (a few thousand 3-D and 2-D
variables, ``L`` of a few hundred thousand entries) GTSAM's multifrontal elimination costs
6-11 µs per variable (per-clique dense containers and scatters), 9-20× this compiled
factorisation, and building its ``JacobianFactor`` objects from Python costs more than the
numpy linearisation itself; a whole Gauss-Newton iteration is 3.6-6.8× cheaper here
(``scripts/bench_graph.py``, ``docs/benchmarks.md``).  The solution equals GTSAM's to rounding
(the sums are taken in another order); ``SolverConfig.linear_solver`` chooses.
"""

from __future__ import annotations

import signal
from collections.abc import Callable
from dataclasses import dataclass

import gtsam
import numpy as np
from numba import njit
from numpy.typing import NDArray

from slam.errors import EstimationError

__all__ = ["BlockTerms", "NormalEquations", "fill_reducing_order"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

jit = njit(cache=True, nogil=True)


# -- compiled kernels -------------------------------------------------------------------------
@jit
def _symbolic(n: int, Ap: IntArray, Ai: IntArray) -> tuple[IntArray, IntArray]:
    """Elimination tree and column counts of ``L`` for the upper triangle ``(Ap, Ai)``."""
    work = np.full(n, -1, np.int64)
    counts = np.zeros(n, np.int64)
    parent = np.full(n, -1, np.int64)
    for j in range(n):
        work[j] = j
        for p in range(Ap[j], Ap[j + 1]):
            i = Ai[p]
            while i < j and work[i] != j:
                if parent[i] == -1:
                    parent[i] = j
                counts[i] += 1
                work[i] = j
                i = parent[i]
    return parent, counts


@jit
def _factor(
    n: int,
    Ap: IntArray,
    Ai: IntArray,
    Ax: FloatArray,
    Lp: IntArray,
    parent: IntArray,
    Li: IntArray,
    Lx: FloatArray,
    D: FloatArray,
) -> int:
    """Up-looking ``LDLᵀ`` of the upper triangle ``(Ap, Ai, Ax)`` into ``(Lp, Li, Lx)``, ``D``.

    Returns ``-1``, or the first column whose pivot is not positive (not positive definite).
    """
    y = np.zeros(n)
    pattern = np.empty(n, np.int64)
    stack = np.empty(n, np.int64)
    nxt = Lp[:n].copy()
    mark = np.zeros(n, np.bool_)
    for k in range(n):
        top = 0
        d = 0.0
        for p in range(Ap[k], Ap[k + 1]):
            i = Ai[p]
            if i == k:
                d = Ax[p]
                continue
            y[i] = Ax[p]
            if mark[i]:
                continue
            # the path from i up the elimination tree to the first node already seen
            m = 0
            while i != -1 and i < k and not mark[i]:
                mark[i] = True
                stack[m] = i
                m += 1
                i = parent[i]
            while m > 0:
                m -= 1
                pattern[top] = stack[m]
                top += 1
        for t in range(top - 1, -1, -1):
            c = pattern[t]
            q = nxt[c]
            yc = y[c]
            for j in range(Lp[c], q):
                y[Li[j]] -= Lx[j] * yc
            lkc = yc / D[c]
            Li[q] = k
            Lx[q] = lkc
            d -= yc * lkc
            nxt[c] = q + 1
            y[c] = 0.0
            mark[c] = False
        if not d > 0.0:
            return k
        D[k] = d
    return -1


@jit
def _solve(
    n: int, Lp: IntArray, Li: IntArray, Lx: FloatArray, D: FloatArray, x: FloatArray
) -> None:
    """``x ← (L D Lᵀ)⁻¹ x`` in place."""
    for i in range(n):
        xi = x[i]
        for j in range(Lp[i], Lp[i + 1]):
            x[Li[j]] -= Lx[j] * xi
    for i in range(n):
        x[i] /= D[i]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for j in range(Lp[i], Lp[i + 1]):
            s -= Lx[j] * x[Li[j]]
        x[i] = s


@jit
def _symmetric_product(
    n: int, Ap: IntArray, Ai: IntArray, Ax: FloatArray, x: FloatArray
) -> FloatArray:
    """``H x`` for ``H`` given by its upper triangle ``(Ap, Ai, Ax)``."""
    y = np.zeros(n)
    for j in range(n):
        xj = x[j]
        s = 0.0
        for p in range(Ap[j], Ap[j + 1]):
            i = Ai[p]
            v = Ax[p]
            s += v * x[i]
            if i != j:
                y[i] += v * xj
        y[j] += s
    return y


# -- ordering ---------------------------------------------------------------------------------
def fill_reducing_order(
    dims: IntArray, pairs_a: IntArray, pairs_b: IntArray, method: str = "colamd"
) -> IntArray:
    """Elimination order of variables ``0..V-1`` coupled by the pairs ``(a, b)``.

    GTSAM's COLAMD (or METIS) on a symbolic graph with one binary factor per distinct coupled
    pair (and a unary one per uncoupled variable): the ordering GTSAM's elimination would use
    for the same adjacency.  Returns the variables in elimination order.

    METIS fails when SIGTERM arrives while it runs and returns part of an ordering, the signal
    lost; it is then sent to the process again (a run started by the command line stops
    cleanly at its next safe point; without a handler SIGTERM ends the process, as it was
    meant to) and COLAMD orders the variables instead.
    """
    V = dims.shape[0]
    lo, hi = np.minimum(pairs_a, pairs_b), np.maximum(pairs_a, pairs_b)
    keys = np.unique(lo.astype(np.int64) * V + hi)
    sfg = gtsam.SymbolicFactorGraph()
    push = sfg.push_factor
    for a, b in zip((keys // V).tolist(), (keys % V).tolist(), strict=True):
        push(a, b)
    alone = np.ones(V, bool)
    alone[pairs_a] = False
    alone[pairs_b] = False
    if method == "metis":
        # METIS orders the coupled variables; an uncoupled one (no factor shares it) comes
        # last (GTSAM's METIS wrapper does not take a variable without neighbours)
        coupled: list[int] = []
        if keys.size:
            ordering = gtsam.Ordering.MetisSymbolicFactorGraph(sfg)
            coupled = [ordering.at(i) for i in range(ordering.size())]
        if len(coupled) != V - int(alone.sum()):
            # METIS fails when SIGTERM arrives while it runs ("METIS failed during Nested
            # Dissection ordering!") and the signal does not reach the process: it is sent
            # again (a run records it and stops at its next safe point, slam.interrupts), and
            # COLAMD orders the variables instead
            signal.raise_signal(signal.SIGTERM)
            return fill_reducing_order(dims, pairs_a, pairs_b, "colamd")
        order = np.array(coupled + np.flatnonzero(alone).tolist(), dtype=np.int64)
    else:
        for v in np.flatnonzero(alone).tolist():
            push(v)
        ordering = gtsam.Ordering.ColamdSymbolicFactorGraph(sfg)
        order = np.array([ordering.at(i) for i in range(ordering.size())], dtype=np.int64)
    if order.shape[0] != V:  # pragma: no cover - every variable is in the symbolic graph
        raise EstimationError("the ordering does not cover every variable")
    return order


# -- the system -------------------------------------------------------------------------------
@jit
def _add_diagonal(
    Ax: FloatArray, g: FloatArray, A: FloatArray, b: FloatArray, where: IntArray, first: IntArray
) -> None:
    """Add ``AᵀA`` (upper triangle, at ``where``) and ``Aᵀb`` (at ``first + i``) per factor."""
    k, rows, d = A.shape
    for f in range(k):
        t = 0
        for i in range(d):
            for j in range(i, d):
                s = 0.0
                for q in range(rows):
                    s += A[f, q, i] * A[f, q, j]
                Ax[where[f, t]] += s
                t += 1
            s = 0.0
            for q in range(rows):
                s += A[f, q, i] * b[f, q]
            g[first[f] + i] += s


@jit
def _add_cross(Ax: FloatArray, A_a: FloatArray, A_b: FloatArray, where: IntArray) -> None:
    """Add ``A_aᵀA_b`` per factor at ``where`` (``(k, dim_a, dim_b)``)."""
    k, rows, da = A_a.shape
    db = A_b.shape[2]
    for f in range(k):
        for i in range(da):
            for j in range(db):
                s = 0.0
                for q in range(rows):
                    s += A_a[f, q, i] * A_b[f, q, j]
                Ax[where[f, i, j]] += s


@jit
def _row_indices(
    n: int,
    Ap: IntArray,
    order: IntArray,
    start: IntArray,
    dims: IntArray,
    nb_ptr: IntArray,
    nb_var: IntArray,
) -> IntArray:
    """Row indices of the upper triangle: per column its neighbours' rows, then its own."""
    Ai = np.empty(Ap[n], np.int64)
    for v in order:
        for j in range(dims[v]):
            p = Ap[start[v] + j]
            for t in range(nb_ptr[v], nb_ptr[v + 1]):
                u = nb_var[t]
                for a in range(dims[u]):
                    Ai[p] = start[u] + a
                    p += 1
            for a in range(j + 1):
                Ai[p] = start[v] + a
                p += 1
    return Ai


@dataclass(frozen=True)
class BlockTerms:
    """Structure of ``k`` factors of the same shape: rows ``A_a δ_a (+ A_b δ_b) − b``.

    ``var_a`` / ``var_b`` (``(k,)``, ``var_b`` None for one-variable factors) index the
    variables; ``dim_a`` / ``dim_b`` are their dimensions (the same for every factor).
    """

    var_a: IntArray
    dim_a: int
    var_b: IntArray | None = None
    dim_b: int = 0


class NormalEquations:
    """``H δ = g`` for fixed factors over fixed variables (see the module docstring).

    Parameters
    ----------
    dims : ndarray of int, shape (V,)
        Dimension of each variable; the solution vector stacks them in this order.
    terms : list of BlockTerms
        The factors' structure, in the order their values are given to :meth:`assemble`.
    ordering : {"colamd", "metis"}
    describe : callable, optional
        ``describe(v)``: the name of variable ``v`` in error messages (default
        ``"variable v"``).
    """

    def __init__(
        self,
        dims: IntArray,
        terms: list[BlockTerms],
        ordering: str = "colamd",
        describe: Callable[[int], str] | None = None,
    ) -> None:
        dims = np.asarray(dims, dtype=np.int64)
        self._describe = describe or (lambda v: f"variable {v}")
        V = dims.shape[0]
        self.terms = terms
        self.n = n = int(dims.sum())
        two = [t for t in terms if t.var_b is not None]
        empty = np.zeros(0, np.int64)
        pa = np.concatenate([np.asarray(t.var_a, np.int64) for t in two]) if two else empty
        pb = np.concatenate([np.asarray(t.var_b, np.int64) for t in two]) if two else empty
        order = fill_reducing_order(dims, pa, pb, ordering)
        rank = np.empty(V, np.int64)
        rank[order] = np.arange(V)
        # scalar index of each variable's first component: natural (solution) and permuted
        natural = np.r_[0, np.cumsum(dims)[:-1]].astype(np.int64)
        start = np.empty(V, np.int64)
        start[order] = np.r_[0, np.cumsum(dims[order])[:-1]]
        self._start = start
        self._order = order
        self._order_start = start[order]  # increasing: first permuted index of each in order
        perm = np.empty(n, np.int64)  # permuted position of each natural scalar index
        for d in np.unique(dims).tolist():
            v = np.flatnonzero(dims == d)
            perm[natural[v][:, None] + np.arange(d)] = start[v][:, None] + np.arange(d)
        self._perm = perm
        # block pattern of the upper triangle: pairs (u, v), u eliminated before v, by column
        # block v then row block u
        up = np.where(rank[pa] < rank[pb], pa, pb)
        lo = np.where(rank[pa] < rank[pb], pb, pa)
        pair_key, pair_of = np.unique(rank[lo] * V + rank[up], return_inverse=True)
        col_v = order[pair_key // V]
        row_u = order[pair_key % V]
        nb_count = np.bincount(col_v, minlength=V)
        nb_ptr = np.r_[0, np.cumsum(nb_count)].astype(np.int64)
        by_var = np.argsort(col_v, kind="stable")  # pairs grouped by v (ascending rank of u)
        nb_var = row_u[by_var]
        # offset of each pair's rows within its column, and the rows above each diagonal block
        row_dims = dims[nb_var]
        cum = np.cumsum(row_dims) - row_dims  # exclusive, over all pairs
        group_first = np.repeat(nb_ptr[:-1], nb_count)
        offset_sorted = cum - cum[group_first] if cum.size else cum
        offset = np.empty_like(offset_sorted)
        offset[by_var] = offset_sorted
        above = np.zeros(V, np.int64)
        np.add.at(above, col_v, dims[row_u])
        # column pointers: column start[v] + j holds above[v] + j + 1 entries
        col_len = np.empty(n, np.int64)
        for d in np.unique(dims).tolist():
            v = np.flatnonzero(dims == d)
            col_len[start[v][:, None] + np.arange(d)] = above[v][:, None] + np.arange(1, d + 1)
        self.Ap = np.r_[0, np.cumsum(col_len)].astype(np.int64)
        self.Ai = _row_indices(n, self.Ap, order, start, dims, nb_ptr, nb_var.astype(np.int64))
        self.nnz = int(self.Ap[-1])
        self._diag = self.Ap[1:] - 1  # the diagonal closes each column (permuted index)
        # where each factor's entries go
        self._where: list[tuple[IntArray, IntArray | None, IntArray | None]] = []
        k0 = 0
        for t in terms:
            wa = self._diag_where(np.asarray(t.var_a, np.int64), t.dim_a, above)
            if t.var_b is None:
                self._where.append((wa, None, None))
                continue
            vb = np.asarray(t.var_b, np.int64)
            wb = self._diag_where(vb, t.dim_b, above)
            k = vb.shape[0]
            pair = pair_of[k0 : k0 + k]
            k0 += k
            va = np.asarray(t.var_a, np.int64)
            a_first = rank[va] < rank[vb]
            i = np.arange(t.dim_a)[None, :, None]
            j = np.arange(t.dim_b)[None, None, :]
            off = offset[pair][:, None, None]
            # a above b: row start[a] + i in column start[b] + j; else the transpose
            w_ab = self.Ap[start[vb][:, None, None] + j] + off + i
            w_ba = self.Ap[start[va][:, None, None] + i] + off + j
            self._where.append((wa, wb, np.where(a_first[:, None, None], w_ab, w_ba)))
        parent, counts = _symbolic(n, self.Ap, self.Ai)
        self._parent = parent
        self.Lp = np.r_[0, np.cumsum(counts)].astype(np.int64)
        self._Li = np.empty(int(self.Lp[-1]), np.int64)
        self._Lx = np.empty(int(self.Lp[-1]))
        self._D = np.empty(n)
        self.Ax = np.zeros(self.nnz)
        self.g = np.zeros(n)

    def _diag_where(self, var: IntArray, d: int, above: IntArray) -> IntArray:
        """Places of the upper triangle of each variable's diagonal block, ``(k, d(d+1)/2)``."""
        r, c = np.triu_indices(d)
        return self.Ap[self._start[var][:, None] + c] + above[var][:, None] + r

    @property
    def nnz_factor(self) -> int:
        """Entries of ``L`` below the diagonal."""
        return int(self.Lp[-1])

    def assemble(self, values: list[tuple[FloatArray, FloatArray | None, FloatArray]]) -> None:
        """Set ``H`` and ``g`` from each term's ``(A_a, A_b or None, b)`` (pre-whitened).

        ``A_a`` has shape ``(k, rows, dim_a)``, ``A_b`` ``(k, rows, dim_b)``, ``b``
        ``(k, rows)``, for the terms given to the constructor, in order.
        """
        Ax = np.zeros(self.nnz)
        g = np.zeros(self.n)
        for t, (A_a, A_b, b), (wa, wb, wab) in zip(self.terms, values, self._where, strict=True):
            A_a = np.ascontiguousarray(A_a, dtype=np.float64)
            b = np.ascontiguousarray(b, dtype=np.float64)
            _add_diagonal(Ax, g, A_a, b, wa, self._start[t.var_a])
            if t.var_b is not None:
                assert A_b is not None and wb is not None and wab is not None
                A_b = np.ascontiguousarray(A_b, dtype=np.float64)
                _add_diagonal(Ax, g, A_b, b, wb, self._start[t.var_b])
                _add_cross(Ax, A_a, A_b, wab)
        self.Ax = Ax
        self.g = g

    def solve(self, damping: FloatArray | None = None) -> FloatArray:
        """``δ`` (natural order) solving ``(H + diag(damping)) δ = g``.

        ``damping`` is per natural scalar index (default none).  Raises EstimationError when
        the matrix is not positive definite, naming the variable of the first pivot that is
        not positive.
        """
        Ax = self.Ax
        if damping is not None:
            Ax = Ax.copy()
            Ax[self._diag[self._perm]] += damping
        bad = _factor(
            self.n, self.Ap, self.Ai, Ax, self.Lp, self._parent, self._Li, self._Lx, self._D
        )
        if bad >= 0:
            v = int(self._order[np.searchsorted(self._order_start, bad, side="right") - 1])
            raise EstimationError(
                "linear system could not be solved: not positive definite at "
                f"{self._describe(v)} (too few factors determine it, or too ill-conditioned)"
            )
        x = self.g.copy()
        _solve(self.n, self.Lp, self._Li, self._Lx, self._D, x)
        return x[self._perm]

    def predicted_decrease(self, delta: FloatArray) -> float:
        """``½‖b‖² − ½‖A δ − b‖² = gᵀδ − ½ δᵀHδ`` of the undamped system (natural order)."""
        x = np.empty(self.n)
        x[self._perm] = delta
        Hx = _symmetric_product(self.n, self.Ap, self.Ai, self.Ax, x)
        return float(self.g[self._perm] @ delta - 0.5 * (x @ Hx))
