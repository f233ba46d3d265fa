"""Stochastic subspace identification: SSI-cov, SSI-data and input-output SSI.

Each method ends in one extended observability matrix ``O`` with ``max_order`` columns, obtained
from one SVD. Every smaller model order ``n`` uses the first ``n`` columns of the same matrix, and
the system matrix ``A`` of every order is read off two QR factorisations of the shifted halves of
``O`` (:func:`poles_all_orders`), so the whole stabilization diagram costs one factorisation.

``A`` is estimated two ways (the building paper's spurious-mode check):

* forward least squares   ``A_f = (O_up^T O_up)^-1 O_up^T O_dn``   (minimises ||O_up A - O_dn||)
* backward least squares  ``A_b = (O_dn^T O_up)^-1 O_dn^T O_dn``   (inverse of the least-squares
  solution of ``O_dn A^-1 = O_up``).

Both are consistent for noise-free data and differ when the shift-invariance of ``O`` is only
approximate, which is where spurious (noise/mathematical) poles live. Note: the expression printed
as the paper's eq. 13, ``(O_up^T O_dn)^-1 (O_up^T O_up)``, is exactly ``A_f^-1`` and would give
inverted poles (|mu| > 1); it is provided only as :func:`printed_eq13_estimate` for the test that
demonstrates this.

The block-Hankel products are never formed as big explicit matrices:

* SSI-cov: output correlations for all lags come from segmented FFTs whose cross spectra are
  summed before short inverse transforms (:func:`correlations`).
* SSI-data / input-output: the lower-triangular factor ``L`` of the LQ factorisation
  ``H / sqrt(j) = L Q^T`` of the data block-Hankel matrix is computed either from the exactly
  assembled Gram matrix ``H H^T`` (Cholesky; its entries are lag products with exact edge
  corrections, :func:`hankel_gram`) or by a streamed QR over column chunks of ``H^T``
  (:func:`hankel_lq_streamed`). Both give the same ``L`` up to column signs; the Gram route is the
  fast default and falls back to the streamed QR if the Gram matrix is not numerically positive
  definite.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft
import scipy.linalg as sla

from shm_ros.core import eigen
from shm_ros.core.modal import mac_matrix

__all__ = [
    "SubspaceModel",
    "PoleSet",
    "correlations",
    "hankel_gram",
    "hankel_lq_streamed",
    "ssi_cov",
    "ssi_data",
    "ssi_data_leave_one_out",
    "observability_from",
    "ssi_io",
    "poles_all_orders",
    "printed_eq13_estimate",
    "forward_backward_A",
    "two_a_partners",
    "BackwardCheck",
]


@dataclass
class SubspaceModel:
    """Result of the subspace step: the extended observability matrix of the largest order."""

    observability: np.ndarray  # (n_outputs * n_block_rows, max_order)
    singular_values: np.ndarray
    n_outputs: int
    sample_rate_hz: float
    method: str
    block_rows: int


@dataclass
class PoleSet:
    """All poles of all model orders (one row per pole with positive imaginary part)."""

    order: np.ndarray  # (P,) int
    frequency_hz: np.ndarray  # (P,)
    damping_ratio: np.ndarray  # (P,)
    shape: np.ndarray  # (P, n_outputs) complex, unit 2-norm
    # The same pole from the second (backward) estimate of A, matched by frequency:
    frequency_b_hz: np.ndarray  # (P,) nan where A_b has no pole
    damping_b: np.ndarray  # (P,)
    mac_b: np.ndarray  # (P,)
    orders: np.ndarray  # the model orders evaluated

    def __len__(self) -> int:
        return int(self.order.size)

    def subset(self, mask: np.ndarray) -> PoleSet:
        return PoleSet(self.order[mask], self.frequency_hz[mask], self.damping_ratio[mask],
                       self.shape[mask], self.frequency_b_hz[mask], self.damping_b[mask],
                       self.mac_b[mask], self.orders)


# ----------------------------------------------------------------------------- correlations / LQ


def correlations(y: np.ndarray, refs: np.ndarray, n_lags: int, segment: int | None = None) -> np.ndarray:
    """Unbiased output correlations ``R_k = E[y_{t+k} y_ref,t^T]`` for ``k = 0..n_lags-1``.

    ``y`` is (N, n_out); returns (n_lags, n_out, r). Exact finite sums divided by ``N - k``, computed by
    FFT in segments: the sum over ``t`` is split into blocks of ``B`` samples; each block of the
    references (zero-padded) is correlated with the outputs of the same block plus ``n_lags``
    samples ahead, with an FFT of length ``P >= B + n_lags`` so that no lag wraps around. The
    cross spectra are summed over blocks before the inverse FFTs, which are then short
    (``n_out * r`` transforms of length ``P`` instead of ``N``).

    ``segment`` (about ``B``; None: chosen from ``N`` and the lags): longer segments cost more
    in the inverse transforms (one set per call, of length ``P``), shorter ones more in the
    forward transforms (``N / B`` sets of ``n_out + r``); about ``sqrt(N n_lags) / 2`` balances
    them (a 10-minute 100 Hz record with 80 lags: 1,100 samples, 1.7x faster than 4,096;
    its 1-minute jackknife blocks 4x). The sums are the same to rounding whatever the segment.
    """
    n, n_out = y.shape
    if n_lags >= n:
        raise ValueError(f"{n_lags} correlation lags need more than {n} samples")
    refs = np.asarray(refs, dtype=int)
    if segment is None:
        segment = int(np.sqrt(n * n_lags) / 2)
    p = scipy.fft.next_fast_len(min(max(segment, 4 * n_lags), n) + n_lags, real=True)
    b = p - n_lags  # samples of t per block
    nb = -(-n // b)
    ypad = np.zeros((nb * b + p, n_out))
    ypad[:n] = y
    # outputs y_{s .. s+P-1} of every block (a view), references r_{s .. s+B-1} zero-padded
    ys = np.lib.stride_tricks.sliding_window_view(ypad, p, axis=0)[: nb * b : b]  # (nb, n_out, P)
    fy = scipy.fft.rfft(ys, axis=-1)  # (nb, n_out, F)
    # references: a view when they are all the outputs in order (no copy of the record)
    yr = ypad[: nb * b] if np.array_equal(refs, np.arange(n_out)) else ypad[: nb * b, refs]
    fr = scipy.fft.rfft(yr.reshape(nb, b, refs.size), n=p, axis=1)  # (nb, F, r)
    np.conjugate(fr, out=fr)
    # sum over blocks of conj(F_ref) F_y for every frequency: a batched (n_out x nb) @ (nb x r)
    cross = np.matmul(fy.transpose(2, 1, 0), fr.transpose(1, 0, 2))  # (F, n_out, r)
    r = scipy.fft.irfft(cross, n=p, axis=0)[:n_lags]
    r /= (n - np.arange(n_lags))[:, None, None]
    return r


def hankel_gram(z: np.ndarray, n_blocks: int, n_cols: int) -> np.ndarray:
    """Exact Gram matrix ``H H^T`` of the block-Hankel matrix of ``z`` (N, c).

    ``H`` has ``n_blocks`` block rows ``z[a : a + n_cols]^T`` (a = 0..n_blocks-1). Entry block
    ``(a, b) = sum_{k<n_cols} z_{a+k} z_{b+k}^T`` is built from full-length lag products (FFT) with
    exact corrections for the samples beyond the Hankel's columns, then propagated along block
    diagonals with rank-c updates: O(N c^2 log n_blocks + n_blocks^2 c^2) instead of
    O(N n_blocks^2 c^2).
    """
    n, c = z.shape
    if n_blocks - 1 + n_cols > n:
        raise ValueError("Hankel matrix larger than the data")
    # full[d] = sum_{k=0}^{n-1-d} z_k z_{k+d}^T (the lag products, by segmented FFTs); the first
    # block row needs k < n_cols only
    full = (correlations(z, np.arange(c), n_blocks)
            * (n - np.arange(n_blocks))[:, None, None]).transpose(0, 2, 1)
    g0 = np.empty((n_blocks, c, c))
    for d in range(n_blocks):
        tail = z[n_cols:n - d]
        g0[d] = full[d] - tail.T @ z[n_cols + d:n]
    gram = np.empty((n_blocks, n_blocks, c, c))
    gram[0] = g0
    for a in range(1, n_blocks):
        # block (a, b) = block (a-1, b-1) - z_{a-1} z_{b-1}^T + z_{a-1+n_cols} z_{b-1+n_cols}^T
        cols = np.arange(a, n_blocks)
        prev = gram[a - 1, cols - 1]
        lo = np.einsum("i,bj->bij", z[a - 1], z[cols - 1])
        hi = np.einsum("i,bj->bij", z[a - 1 + n_cols], z[cols - 1 + n_cols])
        gram[a, cols] = prev - lo + hi
    # fill the lower triangle by symmetry
    for a in range(n_blocks):
        for b in range(a):
            gram[a, b] = gram[b, a].T
    return gram.transpose(0, 2, 1, 3).reshape(n_blocks * c, n_blocks * c)


def _hankel_rows(z: np.ndarray, rows: np.ndarray, start: int, stop: int) -> np.ndarray:
    """Columns ``start..stop-1`` of the block-Hankel matrix, transposed: (stop-start, len(rows)).

    ``rows`` holds, per Hankel row, ``block * c + channel``.
    """
    c = z.shape[1]
    block, chan = np.divmod(rows, c)
    k = np.arange(start, stop)
    return z[k[:, None] + block[None, :], chan[None, :]]


def hankel_lq_streamed(z: np.ndarray, rows: np.ndarray, n_cols: int,
                       chunk: int = 8192) -> np.ndarray:
    """Lower-triangular ``L`` with ``H = L Q^T`` for the Hankel rows ``rows`` of ``z``.

    QR of ``H^T`` accumulated over column chunks (R of [R_prev; chunk] each time), so at most one
    chunk of the Hankel matrix exists in memory.
    """
    m = rows.size
    r = np.zeros((0, m))
    for start in range(0, n_cols, chunk):
        stop = min(start + chunk, n_cols)
        block = np.vstack([r, _hankel_rows(z, rows, start, stop)])
        r = sla.qr(block, mode="r", overwrite_a=True, check_finite=False)[0][:m]
    return r.T


# Under ``auto`` the Cholesky factor of the Gram matrix is used only while its smallest pivot is at
# least this fraction of its largest: the Gram matrix then has a condition number below 1e10 and
# ``L`` keeps more than 6 significant digits; below it (band-limited records, e.g. short low-passed
# earthquake records) the streamed QR. The simulated earthquake windows of the peers bench
# (decimated to their band) have 3.6e-4.
GRAM_MIN_PIVOT = 1e-5


def _lq_lower(z: np.ndarray, rows: np.ndarray, n_blocks: int, n_cols: int, method: str) -> np.ndarray:
    """``L`` of the LQ factorisation of the (scaled) Hankel rows, by Gram/Cholesky or streamed QR
    (``auto``: Cholesky while it is well conditioned, see ``GRAM_MIN_PIVOT``)."""
    if method not in ("auto", "gram", "qr"):
        raise ValueError(f"unknown LQ method {method!r} (auto | gram | qr)")
    if method in ("auto", "gram"):
        gram = hankel_gram(z, n_blocks, n_cols)[np.ix_(rows, rows)] / n_cols
        try:
            lower = sla.cholesky(gram, lower=True, check_finite=False)
            pivots = np.abs(np.diag(lower))
            if method == "gram" or pivots.min() >= GRAM_MIN_PIVOT * pivots.max():
                return lower
        except np.linalg.LinAlgError:
            if method == "gram":
                raise
    return hankel_lq_streamed(z, rows, n_cols) / np.sqrt(n_cols)


# ----------------------------------------------------------------------------- subspace methods


def _check(y: np.ndarray, block_rows: int, max_order: int) -> None:
    if y.ndim != 2:
        raise ValueError("data must be (n_samples, n_channels)")
    if block_rows < 2:
        raise ValueError("block_rows must be >= 2")
    if y.shape[0] < 4 * block_rows + 10:
        raise ValueError(f"{y.shape[0]} samples are too few for {block_rows} block rows")
    if not np.all(np.isfinite(y)):
        raise ValueError("data contain NaN or inf")
    if max_order < 1:
        raise ValueError("max_order must be >= 1")


def observability_from(mat: np.ndarray, max_order: int) -> tuple[np.ndarray, np.ndarray]:
    """``O = U_n S_n^(1/2)`` from the leading ``n = max_order`` left singular vectors.

    When ``n`` is well below the rank bound, only the leading part is computed, from the
    eigenvectors of ``M M^T`` (:func:`_leading_eigenvectors`); that squares the condition
    number, so it is used only while ``s_n / s_1 > 1e-6`` (relative error of the singular
    vectors then below ~1e-4 of their gap, far inside the noise) and the full SVD otherwise.
    Returns ``O`` and the singular values computed (all of them, or the leading ``n``).
    """
    m = mat.shape[0]
    n = min(max_order, *mat.shape)
    if 2 * n < m:
        w, v = _leading_eigenvectors(sla.blas.dsyrk(1.0, mat, lower=1), n)
        s = np.sqrt(np.clip(w, 0.0, None))
        if s[0] > 0 and s[-1] > 1e-6 * s[0]:
            return v * np.sqrt(s), s
    u, s, _ = sla.svd(mat, full_matrices=False, check_finite=False, lapack_driver="gesdd")
    return u[:, :n] * np.sqrt(s[:n]), s


def _leading_eigenvectors(g: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``n`` largest eigenvalues (descending) and their eigenvectors of the symmetric ``g``
    (lower triangle referenced; overwritten).

    Tridiagonal form (``dsytrd``), all eigenpairs of the tridiagonal matrix by divide and conquer
    (``dstevd``), then only the ``n`` wanted vectors taken back through the reflectors
    (``dormqr``). This is what ``dsyevr`` with an index range does, except for the tridiagonal
    step: on these Gram matrices (eigenvalues spread over 15 decades, long runs of near-equal
    small ones) its MRRR solver for 100 of 480 vectors costs twice divide and conquer for all.
    """
    m = g.shape[0]
    c, d, e, tau, info = sla.lapack.dsytrd(g, lower=1, lwork=32 * m, overwrite_a=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"dsytrd failed (info {info})")
    w, z, info = sla.lapack.dstevd(d, e, overwrite_d=1, overwrite_e=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"dstevd failed (info {info})")
    v = np.asfortranarray(z[:, : m - n - 1 : -1] if m > n else z[:, ::-1])
    # Q = H(1) ... H(m-1) acts on rows 2..m (dsytrd, lower): the QR-type reflectors of c[1:, :-1]
    v[1:], _, info = sla.lapack.dormqr("L", "N", c[1:, :-1], tau, v[1:], lwork=max(1, 64 * n),
                                       overwrite_c=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"dormqr failed (info {info})")
    return w[: m - n - 1 : -1] if m > n else w[::-1], v


def ssi_cov(y: np.ndarray, fs: float, block_rows: int, max_order: int,
            refs: np.ndarray | None = None) -> SubspaceModel:
    """Covariance-driven SSI with reference channels (block-Hankel of correlations, one SVD)."""
    _check(y, block_rows, max_order)
    refs = np.arange(y.shape[1]) if refs is None else np.asarray(refs, dtype=int)
    i = block_rows
    if max_order > refs.size * i:
        raise ValueError(f"max_order {max_order} exceeds the Toeplitz rank bound "
                         f"{refs.size * i} (references x block rows)")
    r = correlations(y, refs, 2 * i)
    h = block_hankel_of_correlations(r, i)
    o, s = observability_from(h, max_order)
    return SubspaceModel(o, s, y.shape[1], fs, "ssi-cov", i)


def block_hankel_of_correlations(r: np.ndarray, i: int) -> np.ndarray:
    """``H(a, b) = R_{a+b+1}`` (a, b = 0..i-1): future outputs times past references."""
    _, n_out, nr = r.shape
    idx = np.arange(i)[:, None] + np.arange(i)[None, :] + 1
    return r[idx].transpose(0, 2, 1, 3).reshape(i * n_out, i * nr)


WEIGHTINGS = ("pc", "upc", "cva")


def ssi_data(y: np.ndarray, fs: float, block_rows: int, max_order: int,
             refs: np.ndarray | None = None, lq: str = "auto", weighting: str = "pc"
             ) -> SubspaceModel:
    """Data-driven SSI (reference-based past) from the LQ factorisation of the data Hankel matrix.

    ``[Y_p(refs); Y_f] / sqrt(j) = L Q^T``; the projection of the future onto the past is
    ``P = L21 Q1^T``. The extended observability matrix comes from the SVD of ``W1 P W2``:

    * ``"upc"`` (unweighted principal components, ``W1 = W2 = I``): SVD of ``L21``;
    * ``"pc"`` (principal components, ``W2 = Y_p^T (Y_p Y_p^T)^-1/2 Y_p``): left singular
      vectors of ``L21 L11^T = Y_f Y_p^T / j``; modes are ranked by their share of the
      future-past covariance;
    * ``"cva"`` (canonical variate analysis, ``W1 = (Y_f Y_f^T / j)^-1/2``): SVD of
      ``C^-1 L21`` with ``C C^T = L21 L21^T + L22 L22^T``, and ``O = C U S^1/2``.

    UPC whitens the past: when part of the response is coloured and spatially incoherent (local
    excitation seen directly by the accelerometers), such states compete with the structural
    ones for the leading singular directions and low model orders carry a frequency bias that
    shrinks only with the order. PC, the default, does not have that drift.
    """
    if weighting not in WEIGHTINGS:
        raise ValueError(f"ssi-data weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    _check(y, block_rows, max_order)
    n, n_out = y.shape
    refs = np.arange(n_out) if refs is None else np.asarray(refs, dtype=int)
    i = block_rows
    if max_order > refs.size * i:
        raise ValueError(f"max_order {max_order} exceeds references x block rows = {refs.size * i}")
    j = n - 2 * i + 1
    rows, rp = _data_rows(n_out, refs, i)
    lower = _lq_lower(y, rows, 2 * i, j, lq)
    o, s = _weighted_observability(lower, rp, max_order, weighting)
    return SubspaceModel(o, s, n_out, fs, "ssi-data", i)


def _data_rows(n_out: int, refs: np.ndarray, i: int) -> tuple[np.ndarray, int]:
    """Hankel rows of the reference past and the full future, and the number of past rows."""
    past = (np.arange(i)[:, None] * n_out + refs[None, :]).ravel()
    future = ((i + np.arange(i))[:, None] * n_out + np.arange(n_out)[None, :]).ravel()
    return np.concatenate([past, future]), past.size


def _weighted_observability(lower: np.ndarray, rp: int, max_order: int, weighting: str):
    """``O`` and singular values from the LQ factor ``L`` of ``[Y_p; Y_f]`` (see :func:`ssi_data`)."""
    l21 = lower[rp:, :rp]
    if weighting == "upc":
        return observability_from(l21, max_order)
    if weighting == "pc":
        return observability_from(l21 @ lower[:rp, :rp].T, max_order)
    l22 = lower[rp:, rp:]
    c = sla.cholesky(l21 @ l21.T + l22 @ l22.T, lower=True, check_finite=False)
    o, s = observability_from(sla.solve_triangular(c, l21, lower=True, check_finite=False),
                              max_order)
    return c @ o, s


def ssi_data_leave_one_out(y: np.ndarray, fs: float, block_rows: int, max_order: int,
                           refs: np.ndarray | None = None, weighting: str = "pc",
                           n_blocks: int = 10):
    """Jackknife replicates of SSI-data: for each of ``n_blocks`` contiguous blocks of Hankel
    columns, the model from all other columns (yields :class:`SubspaceModel`).

    The Gram matrix of the data Hankel matrix is a sum over its columns, so the Gram matrix of
    each block is computed once (:func:`hankel_gram` of that stretch of data) and each replicate
    is ``(total - block) / columns left``, then Cholesky and the same weighting as :func:`ssi_data`.
    """
    _check(y, block_rows, max_order)
    n, n_out = y.shape
    refs = np.arange(n_out) if refs is None else np.asarray(refs, dtype=int)
    i = block_rows
    j = n - 2 * i + 1
    if n_blocks < 3 or j // n_blocks < 8 * i:
        raise ValueError(f"{n_blocks} blocks of {j // max(n_blocks, 1)} columns are too short for "
                         f"{i} block rows")
    rows, rp = _data_rows(n_out, refs, i)
    edges = np.linspace(0, j, n_blocks + 1).astype(int)
    grams = [hankel_gram(y[a:b + 2 * i - 1], 2 * i, b - a)[np.ix_(rows, rows)]
             for a, b in zip(edges[:-1], edges[1:], strict=True)]
    total = np.sum(grams, axis=0)
    for (a, b), g in zip(zip(edges[:-1], edges[1:], strict=True), grams, strict=True):
        lower = sla.cholesky((total - g) / (j - (b - a)), lower=True, check_finite=False)
        o, s = _weighted_observability(lower, rp, max_order, weighting)
        yield SubspaceModel(o, s, n_out, fs, "ssi-data", i)


def ssi_io(y: np.ndarray, u: np.ndarray, fs: float, block_rows: int, max_order: int,
           lq: str = "qr") -> SubspaceModel:
    """Combined deterministic-stochastic input-output SSI (past-output MOESP).

    LQ factorisation of ``[U_f; U_p; Y_p; Y_f]``; the part of the future outputs that is orthogonal
    to the future inputs and explained by the joint past ``W_p = [U_p; Y_p]`` is ``L32`` (rows Y_f,
    columns W_p), whose column space is that of the extended observability matrix.
    """
    _check(y, block_rows, max_order)
    if u.ndim == 1:
        u = u[:, None]
    if u.shape[0] != y.shape[0]:
        raise ValueError("input and outputs differ in length")
    n, n_out = y.shape
    m = u.shape[1]
    i = block_rows
    if max_order > (m + n_out) * i:
        raise ValueError(f"max_order {max_order} exceeds (inputs + outputs) x block rows")
    z = np.hstack([u, y])
    c = m + n_out
    j = n - 2 * i + 1
    blocks_p = np.arange(i)
    blocks_f = i + np.arange(i)
    uf = (blocks_f[:, None] * c + np.arange(m)[None, :]).ravel()
    up = (blocks_p[:, None] * c + np.arange(m)[None, :]).ravel()
    yp = (blocks_p[:, None] * c + m + np.arange(n_out)[None, :]).ravel()
    yf = (blocks_f[:, None] * c + m + np.arange(n_out)[None, :]).ravel()
    lower = _lq_lower(z, np.concatenate([uf, up, yp, yf]), 2 * i, j, lq)
    a, b = uf.size, uf.size + up.size + yp.size
    o, s = observability_from(lower[b:, a:b], max_order)
    return SubspaceModel(o, s, n_out, fs, "ssi-io", i)


# ----------------------------------------------------------------------------- poles


def forward_backward_A(o: np.ndarray, n_out: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The two estimates of ``A`` for one order ``n`` (reference implementation, plain lstsq)."""
    up, dn = o[:-n_out, :n], o[n_out:, :n]
    a_f = sla.lstsq(up, dn)[0]
    a_b = sla.solve(dn.T @ up, dn.T @ dn)
    return a_f, a_b


def printed_eq13_estimate(o: np.ndarray, n_out: int, n: int) -> np.ndarray:
    """Eq. 13 of the building paper exactly as printed: ``(O_up^T O_dn)^-1 (O_up^T O_up)``.

    This is the inverse of the forward least-squares ``A``; kept only to demonstrate that.
    """
    up, dn = o[:-n_out, :n], o[n_out:, :n]
    return sla.solve(up.T @ dn, up.T @ up)


def _poles(ev: eigen.Eigenvalues, fs: float, inverse: bool = False):
    """Indices (into ``ev.values``), frequencies and damping ratios of the poles with positive
    imaginary part (one per conjugate pair). ``inverse``: the eigenvalues are ``1 / mu``."""
    keep = np.flatnonzero(ev.values.imag > 1e-12)
    with np.errstate(divide="ignore", invalid="ignore"):
        mu = ev.values[keep]
        lam = (-np.log(mu).conj() if inverse else np.log(mu)) * fs
        w = np.abs(lam)
        zeta = -lam.real / w
    return keep, w / (2 * np.pi), zeta


def _regular_size(r: np.ndarray) -> int:
    """Number of leading columns of the triangular ``r`` that are numerically independent."""
    d = np.abs(np.diag(r))
    if d.size == 0 or d.max() == 0:
        return 0
    bad = np.flatnonzero(d <= 1e-12 * d.max())
    return int(bad[0]) if bad.size else d.size


def _leading_block_form(m: np.ndarray, c: np.ndarray, r: np.ndarray, n: int):
    """``(m R^-1)[:n, :n]`` and ``(c R^-1)[:, :n]`` for the upper triangular ``r``."""
    rn = r[:n, :n]
    a = sla.solve_triangular(rn, m[:n, :n].T, trans="T", check_finite=False).T
    cc = sla.solve_triangular(rn, c[:, :n].T, trans="T", check_finite=False).T
    return a, cc


def _near(f1, z1, f2, z2, tf: float, tz: float, std_scale: float = 0.0) -> np.ndarray:
    """(len(f1), len(f2)) bool: frequency within ``tf`` and damping within ``tz`` (relative to
    the first set), the usual frequency/damping criteria; ``std_scale`` s widens both to
    ``s sqrt(zeta / (2 pi f))`` (relative frequency, absolute damping) where that is larger."""
    with np.errstate(divide="ignore", invalid="ignore"):
        w = std_scale * np.sqrt(np.abs(z1[:, None]) / (2 * np.pi * f1[:, None]))
        return ((np.abs(f1[:, None] - f2[None, :]) < np.maximum(tf, w) * f1[:, None])
                & (np.abs(z1[:, None] - z2[None, :]) < np.maximum(tz * np.abs(z1[:, None]), w)))


def _unit_shapes(c: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    phi = c @ vectors
    nrm = np.linalg.norm(phi, axis=0)
    nrm[nrm == 0] = 1.0
    return (phi / nrm).T


def poles_all_orders(model: SubspaceModel, orders: np.ndarray | list[int] | None = None,
                     two_a: bool = True,
                     match_scale: tuple[float, float, float] = (0.01, 0.05, 0.9),
                     shapes_for: tuple[float, float] | None = None,
                     std_scale: float = 0.0) -> PoleSet:
    """Poles of every model order from the one observability matrix.

    ``O_up = Q1 R1`` and ``O_dn = Q2 R2`` are factorised once at the largest order; for the first
    ``n`` columns ``A_f = R1[:n,:n]^-1 (Q1^T O_dn)[:n,:n]`` and
    ``A_b = (Q2^T O_up)[:n,:n]^-1 R2[:n,:n]`` (see module docstring). Each forward pole is paired
    with the backward pole of the same order that is closest in frequency, damping and MAC, each
    difference scaled by ``match_scale`` = (frequency tol, damping tol, MAC minimum); a forward
    pole with no backward pole inside the frequency and damping tolerances keeps the closest one
    in frequency and damping and MAC 0 (it fails the check either way).

    ``shapes_for = (freq_tol, damping_tol)``: mode shapes (eigenvectors) are computed only for
    poles that have a pole within these tolerances at a neighbouring evaluated order, i.e. the
    only poles that can be stable; the others get NaN shapes. ``None``: shapes of every pole.
    Eigenvalues of every order come first, eigenvectors of the chosen poles after
    (:mod:`shm_ros.core.eigen`), which about halves the cost of a diagram.

    ``std_scale`` s widens both sets of tolerances to ``s sqrt(zeta / (2 pi f))`` where larger
    (a multiple of the standard error of frequency and damping, see ``StabilityConfig``).
    """
    o = model.observability
    n_out = model.n_outputs
    fs = model.sample_rate_hz
    nmax = o.shape[1]
    wanted = np.arange(1, nmax + 1) if orders is None else np.asarray(orders, dtype=int)
    evaluated = wanted[(wanted >= 1) & (wanted <= nmax)]
    up, dn = o[:-n_out], o[n_out:]
    c = o[:n_out]
    # Basis in which the upper part of O is orthonormal (O' = O R1^-1, R1 upper triangular, so
    # O'[:, :n] spans the same space as O[:, :n]): there the forward A of order n is the leading
    # n x n block of the single matrix A' = Q1^T O_dn R1^-1, and its eigenvector y gives the mode
    # shape C' y with C' = C R1^-1. Likewise the inverse of the backward A of order n is similar
    # to the leading block of B' = Q2^T O_up R2^-1 (eigenvalues 1/mu, shapes C R2^-1 y).
    q1, r1 = sla.qr(up, mode="economic", check_finite=False)
    nmax = min(nmax, _regular_size(r1))
    a_all, c_f = _leading_block_form(q1.T @ dn, c, r1, nmax)
    if two_a:
        b_all, c_b, nb = _backward_form(o, n_out, nmax)
    # pass 1: eigenvalues of both estimates at every order
    fwd: list[tuple] = []
    for n in evaluated[evaluated <= nmax]:
        try:
            ev = eigen.eigenvalues(a_all[:n, :n], balance=False)
        except (np.linalg.LinAlgError, ValueError):
            continue
        keep, f, z = _poles(ev, fs)
        if f.size == 0:
            continue
        evb = None
        if two_a and n <= nb:
            try:
                evb = eigen.eigenvalues(b_all[:n, :n], balance=False)
            except (np.linalg.LinAlgError, ValueError):
                evb = None
        fwd.append((n, ev, keep, f, z, evb))
    if not fwd:
        e = np.zeros(0)
        return PoleSet(e.astype(int), e, e, np.zeros((0, n_out), complex), e, e, e, evaluated)
    # which poles need a shape: those with a neighbour at the previous or next order
    need = [np.ones(item[3].size, bool) for item in fwd]
    if shapes_for is not None:
        tf, tz = shapes_for
        need = [np.zeros(item[3].size, bool) for item in fwd]
        for k in range(1, len(fwd)):
            _, _, _, f0, z0, _ = fwd[k - 1]
            _, _, _, f1, z1, _ = fwd[k]
            close = _near(f1, z1, f0, z0, tf, tz, std_scale)
            need[k] |= close.any(axis=1)
            need[k - 1] |= close.any(axis=0)
    # pass 2: shapes of the chosen poles and the two-A partners
    cols: dict[str, list] = {k: [] for k in ("order", "f", "z", "phi", "fb", "zb", "macb")}
    for (n, ev, keep, f, z, evb), sel in zip(fwd, need, strict=True):
        phi = np.full((f.size, n_out), np.nan, complex)
        phi[sel] = _unit_shapes(c_f[:, :n], eigen.eigenvectors(ev, keep[sel]))
        fb, zb, macb = _backward_partners(f, z, phi, sel, evb, c_b[:, :n] if evb is not None else None,
                                          fs, match_scale, std_scale)
        cols["order"].append(np.full(f.size, n))
        cols["f"].append(f)
        cols["z"].append(z)
        cols["phi"].append(phi)
        cols["fb"].append(fb)
        cols["zb"].append(zb)
        cols["macb"].append(macb)
    cat = {k: np.concatenate(v) for k, v in cols.items()}
    return PoleSet(cat["order"], cat["f"], cat["z"], cat["phi"], cat["fb"], cat["zb"],
                   cat["macb"], evaluated)


def _backward_form(o: np.ndarray, n_out: int, nmax: int) -> tuple[np.ndarray, np.ndarray, int]:
    """``B' = Q2^T O_up R2^-1`` (``O_dn = Q2 R2``), whose leading ``n x n`` block is similar to
    the inverse of the backward ``A`` of order ``n``, the shape matrix ``C R2^-1`` and the
    largest regular order (see :func:`poles_all_orders`)."""
    up, dn = o[:-n_out], o[n_out:]
    q2, r2 = sla.qr(dn, mode="economic", check_finite=False)
    nb = min(nmax, _regular_size(r2))
    b_all, c_b = _leading_block_form(q2.T @ up, o[:n_out], r2, nb)
    return b_all, c_b, nb


def _backward_partners(f: np.ndarray, z: np.ndarray, phi: np.ndarray, sel: np.ndarray,
                       evb: eigen.Eigenvalues | None, c_b: np.ndarray | None, fs: float,
                       match_scale: tuple[float, float, float], std_scale: float
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequency, damping and MAC of the backward partner of each forward pole of one order
    (``f``, ``z``, shapes ``phi``): the backward pole closest in frequency, damping and MAC
    (each difference scaled by ``match_scale``), searched with shapes for the poles ``sel``; a
    pole outside ``sel`` or with no backward pole inside the tolerances keeps the closest in
    frequency and damping and MAC 0. ``evb``: eigenvalues of the backward ``B'`` block of this
    order (None: no backward estimate, NaN partners)."""
    fb = np.full(f.size, np.nan)
    zb = np.full(f.size, np.nan)
    macb = np.zeros(f.size)
    if evb is None or c_b is None:
        return fb, zb, macb
    tf2, tz2, tm2 = match_scale
    keep2, f2, z2 = _poles(evb, fs, inverse=True)
    if not f2.size:
        return fb, zb, macb
    with np.errstate(divide="ignore", invalid="ignore"):
        dist = (np.abs(f[:, None] - f2[None, :]) / f[:, None] / tf2
                + np.abs(z[:, None] - z2[None, :]) / np.abs(z[:, None]) / tz2)
    dist = np.nan_to_num(dist, nan=np.inf)
    inside = _near(f, z, f2, z2, tf2, tz2, std_scale) & sel[:, None]
    k = np.argmin(dist, axis=1)
    fb, zb = f2[k], z2[k]
    cand = np.flatnonzero(inside.any(axis=0))
    if cand.size:
        phi2 = np.full((f2.size, phi.shape[1]), np.nan, complex)
        # the pole mu = 1/nu with imag(mu) > 0 belongs to conj(nu): conjugate shape
        phi2[cand] = _unit_shapes(c_b, eigen.eigenvectors(evb, keep2[cand])).conj()
        rows = np.flatnonzero(inside.any(axis=1))
        mac = mac_matrix(phi[rows], phi2)
        score = np.where(inside[rows], dist[rows] + (1.0 - np.nan_to_num(mac)) / (1.0 - tm2), np.inf)
        best = np.argmin(score, axis=1)
        fb[rows], zb[rows] = f2[best], z2[best]
        macb[rows] = np.nan_to_num(mac[np.arange(rows.size), best])
    return fb, zb, macb


class BackwardCheck:
    """The second (backward) estimate of ``A`` of one subspace model, solved order by order on
    demand: :meth:`partners` gives chosen poles of one order the backward partner that
    :func:`poles_all_orders` with ``two_a=True`` gives them (the model's ``B'`` is formed once)."""

    def __init__(self, model: SubspaceModel, max_order: int,
                 match_scale: tuple[float, float, float] = (0.01, 0.05, 0.9), std_scale: float = 0.0):
        self.fs = model.sample_rate_hz
        self.match_scale = match_scale
        self.std_scale = std_scale
        self.b_all, self.c_b, self.nb = _backward_form(model.observability, model.n_outputs,
                                                       max_order)

    def partners(self, poles: PoleSet, at: np.ndarray) -> None:
        """Fill ``frequency_b_hz``, ``damping_b`` and ``mac_b`` of the poles ``at`` (indices, all
        of one model order) in place."""
        n = int(poles.order[at[0]])
        if n > self.nb:
            poles.frequency_b_hz[at], poles.damping_b[at], poles.mac_b[at] = np.nan, np.nan, 0.0
            return
        try:
            evb = eigen.eigenvalues(self.b_all[:n, :n], balance=False)
        except (np.linalg.LinAlgError, ValueError):
            evb = None
        sel = np.isfinite(poles.shape[at, 0])
        fb, zb, macb = _backward_partners(poles.frequency_hz[at], poles.damping_ratio[at],
                                          poles.shape[at], sel, evb, self.c_b[:, :n], self.fs,
                                          self.match_scale, self.std_scale)
        poles.frequency_b_hz[at], poles.damping_b[at], poles.mac_b[at] = fb, zb, macb


def two_a_partners(model: SubspaceModel, poles: PoleSet, which: np.ndarray,
                   match_scale: tuple[float, float, float] = (0.01, 0.05, 0.9),
                   std_scale: float = 0.0) -> PoleSet:
    """The two-A check for the poles ``which`` (a mask or indices into ``poles``) alone: the
    backward estimate of ``A`` is solved only at the orders where those poles occur, and only
    they get a backward partner (the others keep theirs, NaN for a diagram made without the
    check). Each checked pole gets what :func:`poles_all_orders` with ``two_a=True`` gives it.

    The building paper presents the second estimate of ``A`` as a validation of modes that
    passed the stabilization criteria; validating the stable candidates only (rather than every
    pole of every order) leaves out the backward eigenvalue problems of the orders without a
    candidate and the backward shapes of the poles that cannot become a mode."""
    idx = np.flatnonzero(which) if np.asarray(which).dtype == bool else np.asarray(which, int)
    out = poles.subset(np.ones(len(poles), bool))
    if idx.size == 0:
        return out
    check = BackwardCheck(model, int(poles.order.max()), match_scale, std_scale)
    for n in np.unique(poles.order[idx]):
        check.partners(out, idx[poles.order[idx] == n])
    return out
