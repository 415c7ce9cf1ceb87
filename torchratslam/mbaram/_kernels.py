"""MBARAM's match kernels compiled with numba (imported lazily by
:mod:`torchratslam.mbaram.compiled`): one pass over the nodes' dimensions per input and
channel, no temporaries.

* :func:`outlier_logp`: the log likelihood of a diagonal laser channel with the beam
  outlier term, ``sum_i logaddexp(log N_i, log U)``, per node. ``logaddexp(a, b)`` is
  ``max(a, b) + log1p(exp(-|a - b|))`` as torch computes it; the maxima are summed and
  the corrections as the log of their product (one ``log`` per 32 beams), ``exp`` by
  :func:`_exp_neg`, a polynomial the loop vectorises;
* :func:`gauss_logp`: Eq. 5 of a diagonal channel (angular dimensions wrapped);
* :func:`normalise`, :func:`combine`: Eqs. 1, 4 and Eq. 3 in log space (logsumexp as
  torch computes it: the maximum, then the log of the sum of the exponentials);
* :func:`updated_logs`, :func:`updated_logs_ang`: Eq. 8's ``log S'`` of a node after
  tentatively learning the input (Eq. 10, floored): for the nodes asked (the lasers,
  whose vigilance is tested on the candidates in order, usually one node) or for all
  nodes of a small channel with angular dimensions (the odometry);
* :func:`learn_diag`: Eqs. 9-10 for one node, in place.

The elementwise operations are the tensor path's (:mod:`torchratslam.mbaram.match`) in
its order; logarithms and exponentials are the C library's or :func:`_exp_neg` (within
a few ulp), and sums run in order where torch sums in blocks, so the last bits of a
node's log likelihood (about -1e3 to -1e4) may differ from the tensor path's (by
~1e-11); the map, the winners and the localisations do not (tested against the tensor
path).

Compiled functions are cached on disk by numba (``cache=True``); the first use in a
fresh environment compiles them (a few seconds).
"""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph._jit import njit_cached

_LOG_2PI = math.log(2.0 * math.pi)
_TWO_PI = 2.0 * math.pi
_SKIP_D = 41.6
"""``|a - b|`` above which ``exp(-|a - b|) < 2**-60``, below the last bit of the product
of the corrections (at least 1)."""
_BLOCK = 32
"""Beams whose corrections are multiplied before one ``log`` (a product below 2**32);
a multiple of 4 (the lanes)."""
_INV_STEP = 32.0 / math.log(2.0)
_STEP_HI = 6.93147180369123816490e-01 / 32.0  # fdlibm's split of ln 2: k * _STEP_HI is exact
_STEP_LO = 1.90821492927058770002e-10 / 32.0
_E2, _E3, _E4, _E5, _E6 = (1.0 / math.factorial(c) for c in range(2, 7))
_POW2_NEG = np.array([2.0**-k for k in range(64)])
_POW2_FRAC = np.array([2.0 ** (-j / 32.0) for j in range(32)])


@njit_cached(nogil=True, error_model="numpy", inline="always")
def _exp_neg(g: float) -> float:  # pragma: no cover - compiled
    """``exp(-g)`` for ``0 <= g <= _SKIP_D`` without a library call (so the loop over the
    beams vectorises): ``2**(-k/32) exp(-r)``, ``g = k ln(2) / 32 + r``,
    ``|r| <= ln(2) / 64``, the Taylor series of degree 6 (truncation below 4e-18),
    within a few ulp of exp."""
    k = int(g * _INV_STEP + 0.5)
    r = (g - k * _STEP_HI) - k * _STEP_LO
    p = ((((((_E6 * -r + _E5) * -r + _E4) * -r + _E3) * -r + _E2) * -r + 1.0) * -r) + 1.0
    return p * (_POW2_NEG[(k >> 5) & 63] * _POW2_FRAC[k & 31])


@njit_cached(nogil=True, error_model="numpy")
def outlier_logp(  # pragma: no cover - compiled
    x: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    logcov: np.ndarray,
    n: int,
    log_keep: float,
    log_u: float,
) -> np.ndarray:
    """Per node ``sum_i logaddexp(log((1 - eps) N(x_i; mu_ji, s2_ji)), log_u)``.

    ``logaddexp(a, b) = max(a, b) + log1p(exp(-|a - b|))``; the maxima are summed, and
    the corrections as the log of their product ``prod (1 + exp(-|a - b|))``, taken
    every :data:`_BLOCK` beams (at most ``2**_BLOCK``): one ``log`` per block instead
    of one ``log1p`` per beam; a beam with ``|a - b| > _SKIP_D`` (far from the node's
    mean) adds its maximum only. Sums and products run over four interleaved lanes.

    Args:
        x: the input. Shape: (D,).
        mean, cov, logcov: the channel's node statistics. Shape: (>= n, D).
        n: the nodes.
        log_keep: ``log1p(-eps)``.
        log_u: ``log(eps / R)``.

    Returns:
        Shape: (n,).
    """
    dim = x.shape[0]
    padded = -(-dim // _BLOCK) * _BLOCK
    mx = np.zeros(padded)  # the padding adds 0 and multiplies by 1
    y = np.zeros(padded)
    out = np.empty(n)
    for j in range(n):
        mj, cj, lj = mean[j], cov[j], logcov[j]
        for i in range(dim):
            d = x[i] - mj[i]
            r = d * d / cj[i]
            logn = (r + lj[i] + _LOG_2PI) * -0.5 + log_keep
            g = abs(logn - log_u)
            mx[i] = max(logn, log_u)
            y[i] = _exp_neg(min(g, _SKIP_D)) if g < _SKIP_D else 0.0
        s0 = s1 = s2 = s3 = 0.0
        corr = 0.0
        for b in range(0, padded, _BLOCK):
            p0 = p1 = p2 = p3 = 1.0
            for i in range(b, b + _BLOCK, 4):
                s0 += mx[i]
                s1 += mx[i + 1]
                s2 += mx[i + 2]
                s3 += mx[i + 3]
                p0 *= 1.0 + y[i]
                p1 *= 1.0 + y[i + 1]
                p2 *= 1.0 + y[i + 2]
                p3 *= 1.0 + y[i + 3]
            corr += math.log((p0 * p1) * (p2 * p3))
        out[j] = ((s0 + s1) + (s2 + s3)) + corr
    return out


@njit_cached(nogil=True, error_model="numpy")
def updated_logs(  # pragma: no cover - compiled
    x: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    logcov: np.ndarray,
    rows: np.ndarray,
    ab: np.ndarray,
    loga: np.ndarray,
    log_floor: float,
) -> np.ndarray:
    """Eq. 8's ``log S'`` of each node in ``rows`` after tentatively learning ``x``:
    ``sum_i max(log1p(a b r_i) + log s2_i + log a, log_floor)`` (Eq. 10, floored).

    Args:
        x: the input. Shape: (D,).
        mean, cov, logcov: the channel's node statistics. Shape: (N', D).
        rows: the nodes. Shape: (K,).
        ab, loga: ``a b`` and ``log a`` of every node. Shape: (N,).
        log_floor: log of the variance floor.

    Returns:
        Shape: (K,).
    """
    dim = x.shape[0]
    out = np.empty(rows.shape[0])
    for k in range(rows.shape[0]):
        j = rows[k]
        mj, cj, lj = mean[j], cov[j], logcov[j]
        abj, laj = ab[j], loga[j]
        s = 0.0
        for i in range(dim):
            d = x[i] - mj[i]
            r = d * d / cj[i]
            v = math.log1p(r * abj) + lj[i] + laj
            s += v if v > log_floor else log_floor
        out[k] = s
    return out


@njit_cached(nogil=True, error_model="numpy")
def gauss_logp(  # pragma: no cover - compiled
    x: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    logdet: np.ndarray,
    ang: np.ndarray,
    n: int,
) -> np.ndarray:
    """Per node Eq. 5 with a diagonal covariance, ``-0.5 (D log 2pi + log det + q)``,
    ``q = sum_i (x_i - mu_ji)^2 / s2_ji``; angular dimensions (``ang``) wrapped to
    ``[-pi, pi)`` first. Shape: (n,)."""
    dim = x.shape[0]
    out = np.empty(n)
    for j in range(n):
        q = 0.0
        for i in range(dim):
            d = x[i] - mean[j, i]
            if ang[i]:
                d = (d + math.pi) % _TWO_PI - math.pi
            q += d * d / cov[j, i]
        out[j] = -0.5 * (dim * _LOG_2PI + logdet[j] + q)
    return out


@njit_cached(nogil=True, error_model="numpy")
def normalise(logp: np.ndarray, logprior: np.ndarray) -> np.ndarray:  # pragma: no cover
    """Eqs. 1, 4 in log space: ``joint - logsumexp(joint)``, ``joint = logp + logprior``."""
    n = logp.shape[0]
    joint = logp + logprior
    m = joint.max()
    if not math.isfinite(m):
        m = 0.0
    s = 0.0
    for j in range(n):
        s += math.exp(joint[j] - m)
    return joint - (math.log(s) + m)


@njit_cached(nogil=True, error_model="numpy")
def combine(terms: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Eq. 3 in log space: ``logsumexp`` over the channels (rows) of
    ``log alpha_k + log P(w_j | x_k)``. Shape: (K, n) -> (n,)."""
    k, n = terms.shape
    out = np.empty(n)
    for j in range(n):
        m = terms[0, j]
        for c in range(1, k):
            m = max(m, terms[c, j])
        if not math.isfinite(m):
            out[j] = m
            continue
        s = 0.0
        for c in range(k):
            s += math.exp(terms[c, j] - m)
        out[j] = math.log(s) + m
    return out


@njit_cached(nogil=True, error_model="numpy")
def updated_logs_ang(  # pragma: no cover - compiled
    x: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    logcov: np.ndarray,
    ang: np.ndarray,
    n: int,
    ab: np.ndarray,
    loga: np.ndarray,
    log_floor: float,
) -> np.ndarray:
    """:func:`updated_logs` of the first ``n`` nodes of a small channel with angular
    dimensions (``ang``, differences wrapped to ``[-pi, pi)``). Shape: (n,)."""
    dim = x.shape[0]
    out = np.empty(n)
    for j in range(n):
        s = 0.0
        for i in range(dim):
            d = x[i] - mean[j, i]
            if ang[i]:
                d = (d + math.pi) % _TWO_PI - math.pi
            v = math.log1p(d * d / cov[j, i] * ab[j]) + logcov[j, i] + loga[j]
            s += v if v > log_floor else log_floor
        out[j] = s
    return out


@njit_cached(nogil=True, error_model="numpy")
def learn_diag(  # pragma: no cover - compiled
    mean: np.ndarray,
    cov: np.ndarray,
    logcov: np.ndarray,
    logdet: np.ndarray,
    j: int,
    x: np.ndarray,
    ang: np.ndarray,
    a: float,
    b: float,
    floor: float,
) -> None:
    """Learn ``x`` into node ``j`` of a diagonal channel, in place (Eqs. 9-10):
    ``mu += b d``, ``s2 = max(a s2 + b (a d)^2, floor)``, angular dimensions wrapped to
    ``[-pi, pi)``; ``logcov``, ``logdet`` follow."""
    s = 0.0
    for i in range(x.shape[0]):
        d = x[i] - mean[j, i]
        if ang[i]:
            d = (d + math.pi) % _TWO_PI - math.pi
        mu = mean[j, i] + b * d  # Eq. 9
        if ang[i]:
            mu = (mu + math.pi) % _TWO_PI - math.pi
        dn = a * d
        v = a * cov[j, i] + b * (dn * dn)  # Eq. 10
        v = v if v > floor else floor
        cov[j, i] = v
        lv = math.log(v)
        logcov[j, i] = lv
        s += lv
        mean[j, i] = mu
    logdet[j] = s
