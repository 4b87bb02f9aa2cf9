"""Weighted least squares and SBAS protection levels, vectorised over epochs (DO-229D J.1).

Per epoch, with G the (n, 4) geometry matrix in east-north-up (rows [-cos E sin A, -cos E cos A,
-sin E, 1]) and W = diag(1 / sigma_i^2), the position correction is (G^T W G)^-1 G^T W y and
D = (G^T W G)^-1 gives d_east^2, d_north^2, d_EN and d_U^2. HPL = K_H d_major with
d_major = sqrt((d_E^2 + d_N^2) / 2 + sqrt(((d_E^2 - d_N^2) / 2)^2 + d_EN^2)) and VPL = K_V d_U
(DO-229D J.1; K_H = 6.0 for PA, 6.18 for NPA, K_V = 5.33).

Epochs are processed together: the satellites of each epoch fill the slots of padded arrays (unused
slots have zero weight), laid out by (column, slot, epoch) so that the normal matrices of all epochs
are summed slot by slot on contiguous runs, then inverted in one batched ``numpy.linalg.inv``.
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
    if (ep[1:] < ep[:-1]).any():  # rows not in epoch order
        order = np.argsort(ep, kind="stable")
        idx, ep = idx[order], ep[order]
    counts = np.bincount(ep, minlength=n_epochs)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(idx.size) - start[ep]
    width = max(int(counts.max()) if counts.size else 0, 1)
    el, az, y_used = elev[idx], azim[idx], prefit[idx]
    ce = np.cos(el)
    g_used = np.stack([-ce * np.sin(az), -ce * np.cos(az), -np.sin(el), np.ones(idx.size)], axis=-1)
    del el, az, ce
    # by slot: (4, slots, epochs) and (slots, epochs), each (column, slot) a contiguous run over epochs
    cell = slot * n_epochs + ep
    g = np.zeros((4, width, n_epochs))
    for i in range(4):
        g[i].reshape(-1)[cell] = g_used[:, i]
    w = np.zeros((width, n_epochs))
    w.reshape(-1)[cell] = 1.0 / sigma2[idx]
    y = np.zeros((width, n_epochs))
    y.reshape(-1)[cell] = y_used
    del slot, cell
    gw = g * w
    ok = counts >= min_sats
    normal, rhs = _normal_equations(g, gw, y)
    del g, gw, w, y  # the padded arrays: freed before the residuals
    normal[~ok] = np.eye(4)  # placeholders, discarded below
    cov = np.linalg.inv(normal)
    x = np.einsum("eij,ej->ei", cov, rhs)
    de, dn, den, du = cov[:, 0, 0], cov[:, 1, 1], cov[:, 0, 1], cov[:, 2, 2]
    d_major = np.sqrt((de + dn) / 2 + np.sqrt(((de - dn) / 2) ** 2 + den**2))
    nan = np.where(ok, 1.0, np.nan)
    residual = np.full(epoch.size, np.nan)
    residual[idx] = y_used - np.einsum("ki,ki->k", g_used, x[ep])
    residual[idx[~ok[ep]]] = np.nan
    return WlsSolution(
        enu=x[:, :3] * nan[:, None],
        clock=x[:, 3] * nan,
        hpl=k_h * d_major * nan,
        vpl=k_v * np.sqrt(du) * nan,
        nsv=np.where(ok, counts, 0).astype(np.int16),
        residual=residual,
    )


def _normal_equations(g: np.ndarray, gw: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """G^T W G (epochs, 4, 4) and G^T W y (epochs, 4) from G and W G by (column, slot, epoch) and y by (slot,
    epoch), summed over the slots in order from 0 (the sums of ``einsum("eki,ekj->eij")``, bit for bit)."""
    n_epochs = g.shape[2]
    normal = np.zeros((4, 4, n_epochs))
    rhs = np.zeros((4, n_epochs))
    term = np.empty((4, 4, n_epochs))
    for k in range(g.shape[1]):
        np.multiply(gw[:, k, None, :], g[None, :, k, :], out=term)
        normal += term
        np.multiply(gw[:, k, :], y[k], out=term[0])
        rhs += term[0]
    return np.ascontiguousarray(normal.transpose(2, 0, 1)), np.ascontiguousarray(rhs.T)
