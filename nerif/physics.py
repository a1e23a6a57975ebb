"""Physics of BOS in air-dominated gas: refractive index <-> temperature and the normalised field.

Relation (Gladstone-Dale at fixed composition and pressure): ``n - 1 = T0 (n0 - 1) / T``.
Normalisation: ``delta = n / n0 - 1`` (zero in ambient gas), ``sigma = delta / delta_thre`` where
``delta_thre = |delta(T_max)|`` at the hottest expected temperature, so hot gas has sigma in [-1, 0).

Temperatures inferred this way assume that n is temperature-driven (N2-dominated, well-mixed gas).
All functions work on numpy arrays and torch tensors alike.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

T_MIN_PHYSICAL_K = 1.0


def n_from_temperature(T, T0: float, n0: float):
    """Refractive index from temperature [K]: ``n = 1 + T0 (n0 - 1) / T``."""
    return 1.0 + T0 * (n0 - 1.0) / T


def temperature_from_n(n, T0: float, n0: float):
    """Temperature [K] from refractive index: ``T = T0 (n0 - 1) / (n - 1)``; needs ``n > 1``."""
    return T0 * (n0 - 1.0) / (n - 1.0)


def delta_from_n(n, n0: float):
    """Normalised perturbation ``delta = n / n0 - 1``."""
    return n / n0 - 1.0


def n_from_delta(delta, n0: float):
    return n0 * (1.0 + delta)


@dataclass(frozen=True)
class Ambient:
    """Ambient gas state and the scale that makes the network output O(1).

    Attributes:
        T0: ambient temperature [K].
        n0: ambient refractive index.
        T_max: hottest expected temperature [K]; sets ``delta_thre``. None: unknown, for data that are already
            deflections of sigma (the paper's dataset format): ``delta_thre`` is then 1 (deflections and the
            reconstruction stay in sigma units) and no temperature can be inferred.
    """

    T0: float
    n0: float
    T_max: Optional[float]

    def __post_init__(self):
        if not self.n0 > 1.0:
            raise ValueError(f"ambient refractive index n0 must exceed 1, got {self.n0}")
        if not self.T0 >= T_MIN_PHYSICAL_K:
            raise ValueError(f"ambient temperature T0 must be at least {T_MIN_PHYSICAL_K} K, got {self.T0}")
        if self.T_max is not None and not self.T_max > self.T0:
            raise ValueError(f"hottest expected temperature T_max={self.T_max} K must exceed T0={self.T0} K")

    @property
    def temperature_known(self) -> bool:
        """Whether sigma maps to temperatures (``T_max`` given)."""
        return self.T_max is not None

    @property
    def deflection_unit(self) -> str:
        """The unit of the deflections: ``rad`` where sigma maps to temperatures, else ``sigma`` (the data are
        deflections of sigma: no physical scale)."""
        return "rad" if self.temperature_known else "sigma"

    @property
    def delta_thre(self) -> float:
        """``|delta|`` at ``T_max`` (dimensionless, ~1e-4 in air); 1 when ``T_max`` is unknown."""
        if self.T_max is None:
            return 1.0
        return float(abs(delta_from_n(n_from_temperature(self.T_max, self.T0, self.n0), self.n0)))

    def sigma_from_temperature(self, T):
        return delta_from_n(n_from_temperature(T, self.T0, self.n0), self.n0) / self.delta_thre

    def temperature_from_sigma(self, sigma):
        """Temperature [K] from the normalised field; sigma must keep ``n > 1`` (sigma > -1 / (1 - T0/inf))."""
        n = n_from_delta(sigma * self.delta_thre, self.n0)
        return temperature_from_n(n, self.T0, self.n0)

    def n_from_sigma(self, sigma):
        return n_from_delta(sigma * self.delta_thre, self.n0)


def check_temperature(T: np.ndarray, what: str) -> None:
    """Raise a clear error for NaN/inf or unphysical (< 1 K) temperatures."""
    T = np.asarray(T)
    if not np.all(np.isfinite(T)):
        raise ValueError(f"{what} contains {int(np.sum(~np.isfinite(T)))} NaN or infinite values")
    if T.min() < T_MIN_PHYSICAL_K:
        raise ValueError(f"{what} has a temperature of {T.min():.3g} K, below {T_MIN_PHYSICAL_K:g} K: not physical")
