"""Hyperelastic and linear elastic constitutive models as pure functions of F.

Every model maps in-plane deformation gradients ``F`` of shape (..., 2, 2) and Lame parameters
broadcastable to ``F.shape[:-2]`` to the first Piola-Kirchhoff stress ``P`` (..., 2, 2), the
tangent ``A = dP/dF`` (..., 2, 2, 2, 2) and the strain energy density ``W`` (...). Plane strain
(F_33 = 1) unless stated; the out-of-plane Cauchy stress is given by :func:`cauchy_stress`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

_I2 = np.eye(2)
MaterialKind = Literal["linear_elastic", "neo_hookean"]


class MaterialError(ValueError):
    """Non-physical material parameters."""


@dataclass(frozen=True)
class Material:
    """Material parameters of one body: kind, Lame constants, density, plane stress flag."""

    kind: MaterialKind
    lam: float
    mu: float
    density: float
    plane_stress: bool = False

    def __post_init__(self) -> None:
        if self.kind not in ("linear_elastic", "neo_hookean"):
            raise MaterialError(f"unknown material model '{self.kind}'")
        if not self.mu > 0.0:
            raise MaterialError(f"shear modulus mu must be > 0, got {self.mu}")
        # Bulk modulus 2D plane strain lambda + mu, 3D lambda + 2 mu / 3: both must be positive.
        if not self.lam + 2.0 * self.mu / 3.0 > 0.0:
            raise MaterialError(f"bulk modulus lambda + 2 mu/3 must be > 0 (lambda={self.lam})")
        if not self.density > 0.0:
            raise MaterialError(f"density must be > 0, got {self.density}")
        if self.plane_stress and self.kind != "linear_elastic":
            raise MaterialError("plane stress is available for the linear elastic model only")

    @classmethod
    def from_young(
        cls, kind: MaterialKind, E: float, nu: float, density: float, plane_stress: bool = False
    ) -> Material:
        """Build from Young's modulus and Poisson's ratio (nu in (-1, 0.5))."""
        if not E > 0.0:
            raise MaterialError(f"Young's modulus E must be > 0, got {E}")
        if not -1.0 < nu < 0.5:
            raise MaterialError(f"Poisson's ratio must satisfy -1 < nu < 0.5, got {nu}")
        lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
        mu = E / (2.0 * (1.0 + nu))
        return cls(kind, lam, mu, density, plane_stress)

    @property
    def effective_lambda(self) -> float:
        """Lambda of the 2D model: plane stress uses 2 lam mu / (lam + 2 mu)."""
        if self.plane_stress:
            return 2.0 * self.lam * self.mu / (self.lam + 2.0 * self.mu)
        return self.lam

    @property
    def young(self) -> float:
        return self.mu * (3.0 * self.lam + 2.0 * self.mu) / (self.lam + self.mu)

    @property
    def poisson(self) -> float:
        return self.lam / (2.0 * (self.lam + self.mu))

    def wave_speed(self) -> float:
        """Dilatational wave speed sqrt((lambda + 2 mu)/rho), for time-step advice."""
        return float(np.sqrt((self.lam + 2.0 * self.mu) / self.density))


def _inv_det(F: NDArray) -> tuple[NDArray, NDArray]:
    det = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
    inv = np.empty_like(F)
    inv[..., 0, 0] = F[..., 1, 1] / det
    inv[..., 1, 1] = F[..., 0, 0] / det
    inv[..., 0, 1] = -F[..., 0, 1] / det
    inv[..., 1, 0] = -F[..., 1, 0] / det
    return inv, det


def neo_hookean(F: NDArray, lam: NDArray, mu: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Compressible Neo-Hookean, W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2 (report 6.4).

    P = mu (F - F^-T) + lam ln J F^-T;
    A_iJkL = mu d_ik d_JL + (mu - lam ln J) Fi_Li Fi_Jk + lam Fi_Ji Fi_Lk with Fi = F^-1.
    """
    P, Finv, lnJ = _neo_hookean_stress(F, lam, mu)
    lam = np.asarray(lam, dtype=float)[..., None, None]
    mu = np.asarray(mu, dtype=float)[..., None, None]
    I1_minus_3 = np.einsum("...iJ,...iJ->...", F, F) - 2.0  # F_33 = 1 in plane strain
    W = 0.5 * mu[..., 0, 0] * I1_minus_3 - mu[..., 0, 0] * lnJ[..., 0, 0]
    W = W + 0.5 * lam[..., 0, 0] * lnJ[..., 0, 0] ** 2
    c1 = (mu - lam * lnJ)[..., None, None]
    A = mu[..., None, None] * np.einsum("ik,JL->iJkL", _I2, _I2)
    A = A + c1 * np.einsum("...Li,...Jk->...iJkL", Finv, Finv)
    A = A + lam[..., None, None] * np.einsum("...Ji,...Lk->...iJkL", Finv, Finv)
    return P, A, W


def _neo_hookean_stress(F: NDArray, lam: NDArray, mu: NDArray
                        ) -> tuple[NDArray, NDArray, NDArray]:
    """P of :func:`neo_hookean` (same arithmetic), with F^-1 and ln J (..., 1, 1)."""
    lam = np.asarray(lam, dtype=float)[..., None, None]
    mu = np.asarray(mu, dtype=float)[..., None, None]
    Finv, J = _inv_det(F)
    lnJ = np.log(J)[..., None, None]
    FinvT = np.swapaxes(Finv, -1, -2)
    return mu * (F - FinvT) + lam * lnJ * FinvT, Finv, lnJ


def linear_elastic(F: NDArray, lam: NDArray, mu: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Small-strain isotropic elasticity: P = sigma(eps), eps = sym(F - I).

    Not objective under large rotations (use Neo-Hookean for finite deformation).
    """
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


def stress_and_tangent(
    kind: MaterialKind, F: NDArray, lam: NDArray, mu: NDArray
) -> tuple[NDArray, NDArray, NDArray]:
    """Dispatch to the model ``kind``: returns (P, A, W)."""
    return MODELS[kind](F, lam, mu)


def cauchy_stress(
    kind: MaterialKind, F: NDArray, lam: NDArray, mu: NDArray, plane_stress: bool = False
) -> tuple[NDArray, NDArray]:
    """In-plane Cauchy stress sigma = P F^T / J and the out-of-plane sigma_33 (the Neo-Hookean
    stress without its tangent, which took most of a VTU frame's von Mises time)."""
    if kind == "neo_hookean":
        P = _neo_hookean_stress(F, lam, mu)[0]
    else:
        P = MODELS[kind](F, lam, mu)[0]
    lam = np.asarray(lam, dtype=float)
    if kind == "linear_elastic":
        sigma = P
        H = F - _I2
        s33 = np.zeros(F.shape[:-2]) if plane_stress else lam * (H[..., 0, 0] + H[..., 1, 1])
        return sigma, s33
    J = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
    sigma = np.einsum("...iJ,...kJ->...ik", P, F) / J[..., None, None]
    return sigma, lam * np.log(J) / J  # P_33 = lam ln J with F_33 = 1


def von_mises(sigma: NDArray, s33: NDArray) -> NDArray:
    """Von Mises equivalent stress of (sigma_2x2, sigma_33)."""
    sxx, syy, sxy = sigma[..., 0, 0], sigma[..., 1, 1], sigma[..., 0, 1]
    return np.sqrt(
        0.5 * ((sxx - syy) ** 2 + (syy - s33) ** 2 + (s33 - sxx) ** 2) + 3.0 * sxy**2
    )
