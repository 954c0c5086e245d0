"""Fast evaluation of the GP kernels `BatchBO` fits (sigma_f^2 Matern_5/2 and Matern_5/2).

    k(a, b) = sigma_f^2 (1 + sqrt(5) r + 5/3 r^2) exp(-sqrt(5) r),
    r^2 = sum_j ((a_j - b_j) / l_j)^2

Written out because scikit-learn's kernel call spends most of its time on input checks, which
dominate the many one-point calls of the acquisition's L-BFGS-B polish; other kernels fall back
to scikit-learn's own.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import solve_triangular
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import ConstantKernel, Matern, Product

SQRT_5 = math.sqrt(5.0)


def cross_kernel(gp: GaussianProcessRegressor, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The fitted kernel of ``gp`` between the rows of A and of B (len(A) x len(B))."""
    split = _matern_parts(gp)
    if split is None:
        return gp.kernel_(A, B)
    amplitude, length_scale = split
    d2 = (((A[:, None, :] - B[None, :, :]) / length_scale) ** 2).sum(-1)
    r = np.sqrt(np.maximum(d2, 0.0))
    return amplitude * (1.0 + SQRT_5 * r + 5.0 / 3.0 * r**2) * np.exp(-SQRT_5 * r)


def prior_variance(gp: GaussianProcessRegressor, A: np.ndarray) -> np.ndarray:
    """The fitted kernel's variance k(a, a) at the rows of A."""
    split = _matern_parts(gp)
    return np.full(len(A), split[0]) if split is not None else gp.kernel_.diag(A)


def posterior(
    gp: GaussianProcessRegressor, U: np.ndarray, K_UX: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Posterior mean and variance of the latent function at the rows of U, given
    K_UX = k(U, X_train), and V = L^-1 K_UX^T (L the Cholesky factor of K + noise I), which the
    posterior covariance with other points needs: mu = K_UX alpha, var = k(u, u) - |V_u|^2."""
    V = solve_triangular(gp.L_, K_UX.T, lower=True, check_finite=False)
    mu = K_UX @ gp.alpha_
    var = prior_variance(gp, U) - np.einsum("ij,ij->j", V, V)
    return mu, var, V


def _matern_parts(gp: GaussianProcessRegressor) -> tuple[float, np.ndarray] | None:
    """(sigma_f^2, length scales) of a sigma_f^2 Matern_5/2 or Matern_5/2 kernel, else None."""
    k = gp.kernel_
    if isinstance(k, Product) and isinstance(k.k1, ConstantKernel):
        amplitude, matern = float(k.k1.constant_value), k.k2
    else:
        amplitude, matern = 1.0, k
    if not (isinstance(matern, Matern) and matern.nu == 2.5):
        return None
    return amplitude, np.asarray(matern.length_scale, dtype=float)
