"""Linearised statistics of a least-squares fit (pure): intervals and the step to the minimum."""

from __future__ import annotations

import math

import numpy as np


def half_widths(jac: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """95 % half-widths of the columns' parameters (in ``jac``'s units) and their covariance:
    ``s^2 (J^T J)^-1``, ``s^2`` the residuals' variance (misfit included) inflated for their
    lag-one correlation; ``inf`` for a column that changes nothing."""
    dof = max(len(r) - jac.shape[1], 1)
    rho = float(np.corrcoef(r[:-1], r[1:])[0, 1]) if len(r) > 3 and np.std(r) > 0 else 0.0
    rho = min(max(rho if math.isfinite(rho) else 0.0, 0.0), 0.999)
    s2 = float(r @ r) / dof * (1 + rho) / (1 - rho)
    jtj = jac.T @ jac
    cov = s2 * np.linalg.pinv(jtj)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    norms = np.sqrt(np.diag(jtj))
    return np.where(norms > 0, 1.96 * sd, math.inf), cov


def gauss_newton_step(jac: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The linearised step from where ``r`` was taken to the least-squares minimum."""
    return np.asarray(-np.linalg.pinv(jac.T @ jac) @ (jac.T @ r))
