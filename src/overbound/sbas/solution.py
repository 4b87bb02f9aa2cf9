"""Weighted least squares and SBAS protection levels, vectorised over epochs (DO-229D J.1).

Per epoch, with G the (n, 4) geometry matrix in east-north-up (rows [-cos E sin A, -cos E cos A,
-sin E, 1]) and W = diag(1 / sigma_i^2), the position correction is (G^T W G)^-1 G^T W y and
D = (G^T W G)^-1 gives d_east^2, d_north^2, d_EN and d_U^2. HPL = K_H d_major with
d_major = sqrt((d_E^2 + d_N^2) / 2 + sqrt(((d_E^2 - d_N^2) / 2)^2 + d_EN^2)) and VPL = K_V d_U
(DO-229D J.1; K_H = 6.0 for PA, 6.18 for NPA, K_V = 5.33).

Epochs are processed together: the satellites of each epoch fill a padded (epochs, slots, 4)
array whose unused slots have zero weight, so the normal matrices are formed and solved in one
batched ``numpy.linalg.solve``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["K_H_NPA", "K_H_PA", "K_V_PA", "WlsSolution", "weighted_least_squares"]

K_H_PA = 6.0
K_H_NPA = 6.18
K_V_PA = 5.33


@dataclass(frozen=True, slots=True)
class WlsSolution:
    """Per epoch: ``enu`` (n, 3) position correction, ``clock`` (m), ``hpl``, ``vpl`` (NaN where no
    solution), ``nsv`` satellites used, ``residual`` per input row (NaN where not used)."""

    enu: np.ndarray
    clock: np.ndarray
    hpl: np.ndarray
    vpl: np.ndarray
    nsv: np.ndarray
    residual: np.ndarray


def weighted_least_squares(
    epoch: np.ndarray,
    n_epochs: int,
    elev: np.ndarray,
    azim: np.ndarray,
    prefit: np.ndarray,
    sigma2: np.ndarray,
    used: np.ndarray,
    *,
    k_h: float = K_H_PA,
    k_v: float = K_V_PA,
    min_sats: int = 4,
) -> WlsSolution:
    """Solve every epoch at once.

    Parameters
    ----------
    epoch : epoch index (0..n_epochs-1) of each satellite row.
    elev, azim : elevation and azimuth (rad) of each row.
    prefit : measured minus modelled range (m), linearised at the reference position.
    sigma2 : total variance sigma_i^2 (m^2) of each row.
    used : rows that enter the solution.
    """
    idx = np.flatnonzero(used)
    ep = epoch[idx]
    order = np.argsort(ep, kind="stable")
    idx, ep = idx[order], ep[order]
    counts = np.bincount(ep, minlength=n_epochs)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(idx.size) - start[ep]
    width = max(int(counts.max()) if counts.size else 0, 1)
    g = np.zeros((n_epochs, width, 4))
    w = np.zeros((n_epochs, width))
    y = np.zeros((n_epochs, width))
    ce = np.cos(elev[idx])
    g[ep, slot] = np.stack(
        [-ce * np.sin(azim[idx]), -ce * np.cos(azim[idx]), -np.sin(elev[idx]), np.ones(idx.size)], axis=-1
    )
    w[ep, slot] = 1.0 / sigma2[idx]
    y[ep, slot] = prefit[idx]
    ok = counts >= min_sats
    gw = g * w[..., None]
    normal = np.einsum("eki,ekj->eij", gw, g)
    normal[~ok] = np.eye(4)  # placeholders, discarded below
    rhs = np.einsum("eki,ek->ei", gw, y)
    cov = np.linalg.inv(normal)
    x = np.einsum("eij,ej->ei", cov, rhs)
    de, dn, den, du = cov[:, 0, 0], cov[:, 1, 1], cov[:, 0, 1], cov[:, 2, 2]
    d_major = np.sqrt((de + dn) / 2 + np.sqrt(((de - dn) / 2) ** 2 + den**2))
    nan = np.where(ok, 1.0, np.nan)
    residual = np.full(epoch.size, np.nan)
    residual[idx] = y[ep, slot] - np.einsum("ki,ki->k", g[ep, slot], x[ep])
    residual[idx[~ok[ep]]] = np.nan
    return WlsSolution(
        enu=x[:, :3] * nan[:, None],
        clock=x[:, 3] * nan,
        hpl=k_h * d_major * nan,
        vpl=k_v * np.sqrt(du) * nan,
        nsv=np.where(ok, counts, 0).astype(np.int16),
        residual=residual,
    )
