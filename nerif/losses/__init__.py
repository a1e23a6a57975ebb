"""Losses: the deflection misfit (:mod:`nerif.losses.deflection`), and the terms on the field
(:mod:`nerif.losses.regularizers`): the ambient boundary condition that fixes the field's constant, total
variation."""
from nerif.losses.deflection import deflection_mse, deflection_terms, weighted_sum
from nerif.losses.regularizers import AmbientBoundary, TotalVariation

__all__ = ["deflection_mse", "deflection_terms", "weighted_sum", "AmbientBoundary", "TotalVariation"]
