"""NumPy oracle of the compiled element kernel (``ntncontact.fem.kernels_numba``), for tests
only: the constitutive laws as vectorized P, A = dP/dF and W of F, and the Q4 internal force,
tangent and energy built from them with einsum. The package has one implementation (the Numba
kernel); this independent one checks it (issue 15: oracles live in tests/). Like the kernel it
takes nodal displacements d and forms F = I + Grad d (positions x of size L would put eps L / h
of round-off into F); the laws themselves are written in F, not in the kernel's forms in H."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ntncontact.fem.q4 import InvertedElementError, reference_gradients

_I2 = np.eye(2)


def check_current_jacobian(F: NDArray) -> None:
    """Raise :class:`InvertedElementError` if det F <= 0 at any Gauss point (the kernel's
    own check is inside its element loop)."""
    det = _det(F)
    bad = det <= 0.0
    if bad.any():
        e = int(np.argwhere(bad)[0, 0])
        raise InvertedElementError(e, float(det[e].min()), "current configuration")


def _det(F: NDArray) -> NDArray:
    return F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]


def _inv_det(F: NDArray) -> tuple[NDArray, NDArray]:
    det = _det(F)
    inv = np.empty_like(F)
    inv[..., 0, 0] = F[..., 1, 1] / det
    inv[..., 1, 1] = F[..., 0, 0] / det
    inv[..., 0, 1] = -F[..., 0, 1] / det
    inv[..., 1, 0] = -F[..., 1, 0] / det
    return inv, det


def neo_hookean(F: NDArray, lam, mu) -> tuple[NDArray, NDArray, NDArray]:
    """Compressible Neo-Hookean, W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2 (report 6.4).

    P = mu (F - F^-T) + lam ln J F^-T;
    A_iJkL = mu d_ik d_JL + (mu - lam ln J) Fi_Li Fi_Jk + lam Fi_Ji Fi_Lk with Fi = F^-1.
    """
    lam = np.asarray(lam, dtype=float)[..., None, None]
    mu = np.asarray(mu, dtype=float)[..., None, None]
    Finv, J = _inv_det(F)
    lnJ = np.log(J)[..., None, None]
    FinvT = np.swapaxes(Finv, -1, -2)
    P = mu * (F - FinvT) + lam * lnJ * FinvT
    I1_minus_3 = np.einsum("...iJ,...iJ->...", F, F) - 2.0  # F_33 = 1 in plane strain
    W = 0.5 * mu[..., 0, 0] * I1_minus_3 - mu[..., 0, 0] * lnJ[..., 0, 0]
    W = W + 0.5 * lam[..., 0, 0] * lnJ[..., 0, 0] ** 2
    c1 = (mu - lam * lnJ)[..., None, None]
    A = mu[..., None, None] * np.einsum("ik,JL->iJkL", _I2, _I2)
    A = A + c1 * np.einsum("...Li,...Jk->...iJkL", Finv, Finv)
    A = A + lam[..., None, None] * np.einsum("...Ji,...Lk->...iJkL", Finv, Finv)
    return P, A, W


def linear_elastic(F: NDArray, lam, mu) -> tuple[NDArray, NDArray, NDArray]:
    """Small-strain isotropic elasticity: P = sigma(eps), eps = sym(F - I)."""
    lam = np.asarray(lam, dtype=float)
    mu = np.asarray(mu, dtype=float)
    H = F - _I2
    eps = 0.5 * (H + np.swapaxes(H, -1, -2))
    tr = eps[..., 0, 0] + eps[..., 1, 1]
    P = lam[..., None, None] * tr[..., None, None] * _I2 + 2.0 * mu[..., None, None] * eps
    W = 0.5 * np.einsum("...ij,...ij->...", P, eps)
    iso = np.einsum("ij,kl->ijkl", _I2, _I2)
    sym = np.einsum("ik,jl->ijkl", _I2, _I2) + np.einsum("il,jk->ijkl", _I2, _I2)
    A = lam[..., None, None, None, None] * iso + mu[..., None, None, None, None] * sym
    A = np.broadcast_to(A, F.shape + (2, 2)).copy()
    return P, A, W


MODELS = {"neo_hookean": neo_hookean, "linear_elastic": linear_elastic}


def stress_and_tangent(kind: str, F: NDArray, lam, mu) -> tuple[NDArray, NDArray, NDArray]:
    """(P, A, W) of the model ``kind``."""
    return MODELS[kind](F, lam, mu)


def element_force_tangent(kind: str, X_e: NDArray, d_e: NDArray, lam: NDArray, mu: NDArray,
                          need_tangent: bool = True):
    """Internal force f_e (ne, 8), tangent K_e (ne, 8, 8) and strain energy (ne,) of Q4
    elements (report (5.10)) at nodal displacements d_e (ne, 4, 2); dof order (a, i) -> 2 a + i."""
    grad, weight = reference_gradients(X_e)
    F = _I2 + np.einsum("eai,egaJ->egiJ", d_e, grad)
    if kind == "neo_hookean":
        check_current_jacobian(F)
    P, A, Wd = stress_and_tangent(kind, F, lam[:, None], mu[:, None])
    gw = grad * weight[..., None, None]
    f = np.einsum("egiJ,egaJ->eai", P, gw).reshape(-1, 8)
    W = np.einsum("eg,eg->e", Wd, weight)
    if not need_tangent:
        return f, None, W
    AG = np.einsum("egiJkL,egbL->egiJbk", A, grad)
    return f, np.einsum("egaJ,egiJbk->eaibk", gw, AG).reshape(-1, 8, 8), W


def oracle_internal(asm, X: NDArray, d: NDArray, need_tangent: bool = True):
    """What ``Assembler.internal(X, d=d)`` returns (force, CSR tangent, energy), from the
    oracle."""
    ne = len(asm.cells)
    fe, Ke, energy = np.empty((ne, 8)), np.empty((ne, 8, 8)), 0.0
    for group in asm.groups:
        idx = group.elements
        cells = asm.cells[idx]
        f, K, W = element_force_tangent(group.kind, X[cells], d[cells], asm.lam[idx],
                                        asm.mu[idx], need_tangent)
        fe[idx] = f
        if need_tangent:
            Ke[idx] = K
        energy += float(W.sum())
    force = np.bincount(asm.edofs.ravel(), weights=fe.ravel(), minlength=asm.ndof)
    return force, asm.pattern.matrix(Ke) if need_tangent else None, energy


def cauchy_stress(
    kind: str, F: NDArray, lam: NDArray, mu: NDArray, plane_stress: bool = False
) -> tuple[NDArray, NDArray]:
    """In-plane Cauchy stress and the out-of-plane sigma_33 at deformation gradients F (..., 2, 2).

    Neo-Hookean: sigma = P F^T / J = (mu (F F^T - I) + lam ln J I) / J, sigma_33 = lam ln J / J
    (F_33 = 1). Linear elastic: sigma = lam tr(eps) I + 2 mu eps, eps = sym(F - I), and
    sigma_33 = lam tr(eps) in plane strain, 0 in plane stress (lam is then the effective one).
    The package's output takes them from the compiled kernel (``kernels_numba.cell_fields``);
    these closed forms in F check it.
    """
    lam = np.asarray(lam, dtype=float)
    mu = np.asarray(mu, dtype=float)
    if kind == "linear_elastic":
        H = F - _I2
        eps = 0.5 * (H + np.swapaxes(H, -1, -2))
        tr = eps[..., 0, 0] + eps[..., 1, 1]
        sigma = lam[..., None, None] * tr[..., None, None] * _I2 + 2.0 * mu[..., None, None] * eps
        return sigma, np.zeros(F.shape[:-2]) if plane_stress else lam * tr
    J = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
    lnJ = np.log(J)
    b = F @ np.swapaxes(F, -1, -2)  # matmul: 1.5x faster than einsum on 90k 2x2 matrices
    sigma = (mu[..., None, None] * (b - _I2) + (lam * lnJ)[..., None, None] * _I2) \
        / J[..., None, None]
    return sigma, lam * lnJ / J


def von_mises(sigma: NDArray, s33: NDArray) -> NDArray:
    """Von Mises equivalent stress of (sigma_2x2, sigma_33)."""
    sxx, syy, sxy = sigma[..., 0, 0], sigma[..., 1, 1], sigma[..., 0, 1]
    return np.sqrt(
        0.5 * ((sxx - syy) ** 2 + (syy - s33) ** 2 + (s33 - sxx) ** 2) + 3.0 * sxy**2
    )


def cell_fields(kind: str, X_e: NDArray, x_e: NDArray, lam: float, mu: float,
                plane_stress: bool = False) -> dict[str, NDArray]:
    """What ``kernels_numba.cell_fields`` computes, per element (ne, 4, 2) of one material:
    Gauss-point Cauchy stress (xx, yy, zz, xy), Green-Lagrange strain (same order), von
    Mises and pressure averaged with the current weights J w; the current area; and F
    averaged with the reference weights w. F is formed from the positions x, and the stress
    in F's closed forms (:func:`cauchy_stress`): the kernel takes both from H = Grad d."""
    grad, weight = reference_gradients(X_e)
    F = np.einsum("eai,egaJ->egiJ", x_e, grad)
    sigma, s33 = cauchy_stress(kind, F, lam, mu, plane_stress)
    E = 0.5 * (np.swapaxes(F, -1, -2) @ F - _I2)
    e33 = (-lam / (2.0 * mu) * (E[..., 0, 0] + E[..., 1, 1]) if plane_stress
           else np.zeros(E.shape[:-2]))
    current = weight * _det(F)
    area = current.sum(axis=1)
    gauss = {
        "stress": np.stack([sigma[..., 0, 0], sigma[..., 1, 1], s33, sigma[..., 0, 1]], -1),
        "strain": np.stack([E[..., 0, 0], E[..., 1, 1], e33, E[..., 0, 1]], -1),
        "von_mises": von_mises(sigma, s33)[..., None],
        "pressure": (-(sigma[..., 0, 0] + sigma[..., 1, 1] + s33) / 3.0)[..., None],
    }
    out = {name: np.einsum("eg,egk->ek", current, v) / area[:, None]
           for name, v in gauss.items()}
    out["area"] = area
    out["F"] = np.einsum("eg,egij->eij", weight, F) / weight.sum(axis=1)[:, None, None]
    return out
