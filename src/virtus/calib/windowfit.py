"""Batched homography fits of padded pixel windows, on numpy or on torch (CPU or CUDA).

:func:`virtus.calib.projector.local_homographies` gathers every board point's window of
decoded pixels into one padded batch and fits them all here: a normalised DLT per window
from one batched 9 x 9 eigen-decomposition, gross errors trimmed, then Gauss-Newton on the
transfer error. The same code runs on numpy arrays or on torch tensors
(:mod:`virtus.calib.arrayspace`): on a GPU a pose's windows take 12-22 ms instead of 91-124
ms of an H100 host's core (the work is elementwise over every padded pixel), so a
calibration observes its poses beside the renderer without the host's cores setting its
pace. torch on the CPU runs the device's code, and the tests hold it to numpy's to
rounding.
"""

from __future__ import annotations

import math
from typing import Any

from virtus.calib.arrayspace import ArraySpace

__all__ = ["fit_windows"]

#: A window needs this fraction of its pixels (inside the window and the image) valid and
#: within the threshold of its fit, and at least :data:`MIN_PIXELS`, else it is NaN.
MIN_VALID_FRACTION = 0.5
#: Fewest valid pixels of a window that is fitted (a homography has 8 parameters).
MIN_PIXELS = 16
#: Trimming rounds before the final inlier set (each: one batched fit, residuals, new set).
TRIM_ROUNDS = 8
#: A round keeps residuals up to this multiple of the window's median residual (or the
#: threshold when larger), so gross decoding errors leave before the fit is trusted.
TRIM_MEDIANS = 3.0
#: Gauss-Newton steps on the transfer error after the DLT (as ``cv2.findHomography``'s
#: Levenberg-Marquardt refinement): on rendered 960 px boards the first step moves the
#: projector points by up to 1e-4 px, a second by < 1e-6 px.
REFINE_STEPS = 1


def fit_windows(
    space: ArraySpace,
    src: Any,
    dst: Any,
    valid: Any,
    inside: Any,
    threshold: float,
) -> Any:
    """(n, 3, 3) float64 homographies src -> dst of padded windows, NaN where fewer than
    ``max(MIN_VALID_FRACTION * inside, MIN_PIXELS)`` pixels are valid or within
    ``threshold`` of the fit.

    Parameters
    ----------
    space : the arrays' :class:`ArraySpace`.
    src, dst : (n, P, 2) float64 points (``dst`` anything finite where not valid).
    valid : (n, P) bool, the pixels that take part.
    inside : (n, P) bool, the pixels that count towards the minimum (valid or not).
    threshold : float, inlier distance in ``dst`` units.

    Notes
    -----
    Works in Hartley-normalised coordinates fixed by the valid pixels (the transfer error
    there is the ``dst`` error times the similarity's scale), where every round reuses the
    same monomials of ``src``. Gross errors are trimmed instead of found by RANSAC: each
    round keeps the pixels within :data:`TRIM_MEDIANS` median residuals (at least the
    threshold) of the last fit, affine first (it cannot bend towards gross errors as a DLT
    can), then projective, and the final set is every pixel within the threshold of the
    last fit.
    """
    xp = space.xp
    need = (MIN_VALID_FRACTION * space.float64(inside).sum(axis=1)).clip(min=MIN_PIXELS)
    usable = space.float64(valid).sum(axis=1) >= need
    out = space.full((len(need), 3, 3), math.nan)
    if not bool(usable.any()):
        return out
    src, dst, valid = src[usable], dst[usable], valid[usable]
    t_src, t_dst = _normalising(space, src, valid), _normalising(space, dst, valid)
    s = src @ t_src[:, :2, :2].swapaxes(1, 2) + t_src[:, None, :2, 2]
    d = dst @ t_dst[:, :2, :2].swapaxes(1, 2) + t_dst[:, None, :2, 2]
    limit_n = threshold * t_dst[:, 0, 0, None]  # the threshold in normalised units
    x, y, u, v = s[..., 0], s[..., 1], d[..., 0], d[..., 1]
    one = xp.ones_like(x)
    monomials = xp.stack([x * x, x * y, x, y * y, y, one], axis=1)  # (n, 6, P)
    targets = xp.stack([one, u, v, u * u + v * v], axis=1)  # (n, 4, P)
    keep = _trim(space, monomials, targets, s, d, valid, limit_n)
    for last in range(TRIM_ROUNDS, 0, -1):
        hn = _dlt(space, monomials, targets, keep)
        residual = _transfer_error(space, hn, s, d)
        with space.quiet():
            within = valid & (residual <= limit_n)
        if space.equal(within, keep):
            break  # the fit of exactly its own inliers
        trimmed = _trimmed(space, residual, valid, limit_n)
        if last == 1 or space.equal(trimmed, keep):
            keep = within
            hn = _dlt(space, monomials, targets, keep)
            break
        keep = trimmed
    hn = _gauss_newton(space, hn, monomials, s, d, keep)
    fitted = xp.linalg.solve(t_dst, hn @ t_src)  # denormalised
    with space.quiet():
        fitted = fitted / fitted[:, 2:3, 2:3]
    bad = (space.float64(keep).sum(axis=1) < need[usable]) | ~xp.isfinite(fitted).all(axis=(1, 2))
    fitted[bad] = math.nan
    out[usable] = fitted
    return out


def _trim(
    space: ArraySpace,
    monomials: Any,
    targets: Any,
    src: Any,
    dst: Any,
    valid: Any,
    limit: Any,
) -> Any:
    """(n, P) pixels kept by trimming rounds of an affine fit: each keeps the valid pixels
    within ``max(limit, TRIM_MEDIANS * median residual)`` of the last fit, until the set
    stops changing (at most :data:`TRIM_ROUNDS`). An affine map cannot bend to gross
    errors as a DLT of them can, so it trims them first."""
    keep = valid
    for _ in range(TRIM_ROUNDS):
        residual = _transfer_error(space, _affine(space, monomials, targets, keep), src, dst)
        with space.quiet():
            if not bool((valid & ~(residual <= limit)).any()):
                return valid  # every pixel within the threshold: nothing to trim
        trimmed = _trimmed(space, residual, valid, limit)
        if space.equal(trimmed, keep):
            break
        keep = trimmed
    return keep


def _trimmed(space: ArraySpace, residual: Any, valid: Any, limit: Any) -> Any:
    """(n, P) the valid pixels whose ``residual`` (n, P) is within ``max(limit,``
    :data:`TRIM_MEDIANS` ``x`` the window's median residual over its valid pixels``)``
    (``limit`` (n, 1)): one trimming round. Writes NaN into ``residual`` where not valid."""
    residual[~valid] = math.nan
    median = _row_medians(space, residual)
    with space.quiet():
        return valid & (residual <= space.xp.maximum(limit, TRIM_MEDIANS * median))


def _row_medians(space: ArraySpace, residual: Any) -> Any:
    """(n, 1) medians of the non-NaN residuals of each row of (n, P), NaN for a row of NaN
    only (an all-NaN, degenerate fit). Without ``np.nanmedian``'s warning for such rows,
    whose silencing (``warnings.catch_warnings``) is not thread-safe: windows are fitted
    in observer threads (:mod:`virtus.calib.observers`)."""
    median = space.full((len(residual), 1), math.nan)
    some = ~space.xp.isnan(residual).all(axis=1)
    if bool(some.any()):
        median[some] = space.row_medians(residual[some])
    return median


def _affine(space: ArraySpace, monomials: Any, targets: Any, weights: Any) -> Any:
    """(n, 3, 3) least-squares affine maps (NaN where singular) of the point sets of
    :func:`_dlt`'s arguments."""
    xp = space.xp
    w = space.float64(weights)
    blocks = _outer_blocks(space, targets[:, :3] * w[:, None], monomials)  # m m^T, u m, v m
    rhs = xp.stack([blocks[:, 1, :, 2], blocks[:, 2, :, 2]], axis=-1)  # (n, 3, 2)
    out = space.full((len(w), 3, 3), math.nan)
    out[:, 2, :2] = 0.0
    out[:, 2, 2] = 1.0
    normal = blocks[:, 0]
    solvable = xp.linalg.cond(normal) < 1e12
    out[solvable, :2] = xp.linalg.solve(normal[solvable], rhs[solvable]).swapaxes(1, 2)
    return out


def _normalising(space: ArraySpace, points: Any, weights: Any) -> Any:
    """(n, 3, 3) similarities moving each padded set's (n, P, 2) weighted centroid to 0 and
    its RMS distance from it to sqrt(2) (Hartley's normalisation)."""
    xp = space.xp
    w = space.float64(weights)
    count = w.sum(axis=1).clip(min=1.0)
    mean = xp.einsum("np,npk->nk", w, points) / count[:, None]
    spread = xp.einsum("np,npk,npk->n", w, points, points) / count - (mean * mean).sum(axis=1)
    scale = math.sqrt(2.0) / xp.where(spread > 0, xp.sqrt(spread.clip(min=0.0)), 1.0)
    T = space.full((len(points), 3, 3), 0.0)  # noqa: N806
    T[:, 0, 0] = scale
    T[:, 1, 1] = scale
    T[:, :2, 2] = -scale[:, None] * mean
    T[:, 2, 2] = 1.0
    return T


def _outer_blocks(space: ArraySpace, q: Any, monomials: Any) -> Any:
    """(n, Q, 3, 3) weighted sums ``sum_p q[n, k, p] m m^T``, ``m = (x, y, 1)``, from the
    monomials (n, 6, P) ``(x^2, xy, x, y^2, y, 1)`` by one batched product: the blocks of
    the DLT and Gauss-Newton normal equations, without their (n, 2P, 9) design matrices."""
    xp = space.xp
    sums = q @ monomials.swapaxes(1, 2)  # (n, Q, 6)
    xx, xy, x1, yy, y1, one = (sums[..., k] for k in range(6))
    rows = [xp.stack(row, axis=-1) for row in ((xx, xy, x1), (xy, yy, y1), (x1, y1, one))]
    return xp.stack(rows, axis=-2)


def _normal_matrix(space: ArraySpace, blocks: Any) -> Any:
    """(n, 9, 9) normal matrix of the rows ``(m, 0, -u m)`` and ``(0, m, -v m)`` from
    :func:`_outer_blocks` of the weights ``(w, w u, w v, w (u^2 + v^2))``."""
    xp = space.xp
    plain, by_u, by_v, by_uv = (blocks[:, k] for k in range(4))
    zero = xp.zeros_like(plain)
    rows = [[plain, zero, -by_u], [zero, plain, -by_v], [-by_u, -by_v, by_uv]]
    return xp.concatenate([xp.concatenate(row, axis=-1) for row in rows], axis=-2)


def _dlt(space: ArraySpace, monomials: Any, targets: Any, weights: Any) -> Any:
    """(n, 3, 3) DLT homographies (``H[2, 2] = 1``; NaN where degenerate or < 4 points) of
    normalised point sets given by their monomials (n, 6, P) and targets (n, 4, P)
    ``(1, u, v, u^2 + v^2)``, each point weighted by ``weights`` (n, P): the eigenvector
    of the smallest eigenvalue of the 9 x 9 normal matrix."""
    xp = space.xp
    w = space.float64(weights)
    normal = _normal_matrix(space, _outer_blocks(space, targets * w[:, None], monomials))
    values, vectors = xp.linalg.eigh(normal)
    H = vectors[..., 0].reshape(-1, 3, 3)  # noqa: N806
    with space.quiet():
        H = H / H[:, 2:3, 2:3]  # noqa: N806
    degenerate = (w.sum(axis=1) < 4) | (values[:, 1] <= 1e-12 * values[:, -1])
    H[degenerate | ~xp.isfinite(H).all(axis=(1, 2))] = math.nan
    return H


def _transfer_error(space: ArraySpace, H: Any, src: Any, dst: Any) -> Any:  # noqa: N803
    """(n, P) distances between ``H`` (n, 3, 3) applied to src (n, P, 2) and dst."""
    h = H.reshape(len(H), 9, 1)
    x, y = src[..., 0], src[..., 1]
    with space.quiet():
        inv = 1.0 / (h[:, 6] * x + h[:, 7] * y + h[:, 8])
        du = (h[:, 0] * x + h[:, 1] * y + h[:, 2]) * inv - dst[..., 0]
        dv = (h[:, 3] * x + h[:, 4] * y + h[:, 5]) * inv - dst[..., 1]
        return space.xp.sqrt(du * du + dv * dv)


def _gauss_newton(
    space: ArraySpace,
    H: Any,  # noqa: N803
    monomials: Any,
    src: Any,
    dst: Any,
    weights: Any,
) -> Any:
    """:data:`REFINE_STEPS` Gauss-Newton steps on the transfer error ``sum w |H(src) -
    dst|^2`` over the 8 entries of each ``H`` (n, 3, 3) with ``H[2, 2] = 1`` (what
    ``cv2.findHomography``'s Levenberg-Marquardt refinement minimises); NaN stays NaN."""
    xp = space.xp
    w = space.float64(weights)
    h = space.copy(H.reshape(len(H), 9)[:, :8])
    ok = xp.isfinite(h).all(axis=1)
    h[~ok] = 0.0
    x, y = src[..., 0], src[..., 1]
    for _ in range(REFINE_STEPS):
        with space.quiet():
            inv = xp.where(ok[:, None], 1.0 / (h[:, None, 6] * x + h[:, None, 7] * y + 1.0), 0.0)
        u = (h[:, None, 0] * x + h[:, None, 1] * y + h[:, None, 2]) * inv
        v = (h[:, None, 3] * x + h[:, None, 4] * y + h[:, None, 5]) * inv
        r_u, r_v = u - dst[..., 0], v - dst[..., 1]
        # Jacobian rows (m, 0, -u m) / den and (0, m, -v m) / den, m = (x, y, 1), without
        # the fixed H[2, 2]: J^T J from w m m^T / den^2, J^T r from w r m / den.
        w2, w1 = w * inv * inv, w * inv
        q = xp.stack(
            [
                w2,
                w2 * u,
                w2 * v,
                w2 * (u * u + v * v),
                w1 * r_u,
                w1 * r_v,
                w1 * (u * r_u + v * r_v),
            ],
            axis=1,
        )
        blocks = _outer_blocks(space, q, monomials)  # m m^T summed; its last column sums m
        jtj = _normal_matrix(space, blocks[:, :4])[:, :8, :8]
        jtr = xp.concatenate([blocks[:, 4, :, 2], blocks[:, 5, :, 2], -blocks[:, 6, :2, 2]], axis=1)
        jtj[~ok] = space.eye(8)
        try:
            h = h - xp.linalg.solve(jtj, jtr[..., None])[..., 0]
        except space.singular_error:
            break  # a singular system: keep the last estimate
    out = xp.concatenate([h, space.full((len(h), 1), 1.0)], axis=1).reshape(-1, 3, 3)
    out[~ok] = math.nan
    return out
