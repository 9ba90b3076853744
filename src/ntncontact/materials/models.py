"""Material parameters.

The constitutive laws (compressible Neo-Hookean, W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2,
and small-strain linear elasticity; plane strain, F_33 = 1, unless stated) are evaluated for the
internal force, tangent and energy by the compiled element kernel (``fem/kernels_numba.py``:
``_material``, and ``_element_em`` for the energy-momentum integrator's algorithmic stress);
tests/element_oracle.py holds an independent NumPy version that checks it. The output's
stresses (``fem.kernels_numba.cell_fields``) take the same ``_material``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

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
