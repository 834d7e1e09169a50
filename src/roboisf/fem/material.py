"""Isotropic linear-elastic material of one body."""

from __future__ import annotations

import math
from dataclasses import dataclass

from roboisf.errors import InputError

__all__ = ["STEEL", "Material"]


@dataclass(frozen=True)
class Material:
    """Isotropic linear-elastic material.

    Attributes
    ----------
    E : float, Pa — Young's modulus (> 0)
    nu : float — Poisson's ratio, in (−1, 0.5); 0.5 (incompressible) is refused because the
        displacement formulation locks there.
    name : str — label written to the result file
    """

    E: float = 210e9
    nu: float = 0.3
    name: str = "steel"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.E) and self.E > 0):
            raise InputError(
                f"Young's modulus must be a positive number of Pa, got {self.E}", field="E"
            )
        if not (math.isfinite(self.nu) and -1.0 < self.nu < 0.5):
            raise InputError(
                f"Poisson's ratio must be in (-1, 0.5) (0.5 is incompressible, which a "
                f"displacement FE model cannot represent), got {self.nu}",
                field="nu",
            )

    @property
    def G(self) -> float:
        """Shear modulus [Pa]."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lame(self) -> tuple[float, float]:
        """Lamé constants ``(λ, μ)`` [Pa]."""
        lam = self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))
        return lam, self.G

    def to_dict(self) -> dict[str, float | str]:
        return {"name": self.name, "E": self.E, "nu": self.nu}


#: Tool steel, the default of every body (E = 210 GPa, ν = 0.3).
STEEL = Material()
