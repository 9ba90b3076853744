"""Material parameters, and the Cauchy and von Mises stresses of the output.

The constitutive laws (compressible Neo-Hookean, W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2,
and small-strain linear elasticity; plane strain, F_33 = 1, unless stated) are evaluated for the
internal force, tangent and energy by the compiled element kernel (``fem/kernels_numba.py``:
``_material``, and ``_element_em`` for the energy-momentum integrator's algorithmic stress);
tests/element_oracle.py holds an independent NumPy version that checks it.
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


def cauchy_stress(
    kind: MaterialKind, F: NDArray, lam: NDArray, mu: NDArray, plane_stress: bool = False
) -> tuple[NDArray, NDArray]:
    """In-plane Cauchy stress and the out-of-plane sigma_33 at deformation gradients F (..., 2, 2).

    Neo-Hookean: sigma = P F^T / J = (mu (F F^T - I) + lam ln J I) / J, sigma_33 = lam ln J / J
    (F_33 = 1). Linear elastic: sigma = lam tr(eps) I + 2 mu eps, eps = sym(F - I), and
    sigma_33 = lam tr(eps) in plane strain, 0 in plane stress (lam is then the effective one).
    The internal force takes the same laws from the compiled kernel (fem/kernels_numba.py).
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
