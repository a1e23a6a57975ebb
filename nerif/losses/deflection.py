"""The data term: misfit of rendered to observed deflections, per gradient operator, and their weighted sum."""
from __future__ import annotations

from typing import Mapping, Optional

import torch


def deflection_terms(eps: Mapping[str, torch.Tensor], eps_obs: torch.Tensor,
                     weight: Optional[torch.Tensor] = None) -> dict:
    """Operator name -> mean over rays of ``|eps_op - eps_obs|^2``, each ray's times its ``weight`` (R,) where
    given; (R, 3) each, normalised units."""
    if weight is None:
        return {name: ((e - eps_obs) ** 2).sum(-1).mean() for name, e in eps.items()}
    return {name: (weight * ((e - eps_obs) ** 2).sum(-1)).mean() for name, e in eps.items()}


def weighted_sum(terms: Mapping[str, torch.Tensor], weights: Mapping[str, float]) -> torch.Tensor:
    """``sum_op lambda_op * term_op`` over the operators with a positive weight."""
    parts = [w * terms[name] for name, w in weights.items() if w > 0]
    if not parts:
        raise ValueError("every gradient-loss weight is zero: nothing to train on (set grad.weights)")
    return torch.stack(parts).sum()


def deflection_mse(eps: Mapping[str, torch.Tensor], eps_obs: torch.Tensor, weights: Mapping[str, float]) -> torch.Tensor:
    """``sum_op lambda_op * mean over rays |eps_op - eps_obs|^2`` over the operators with a positive weight.

    Args:
        eps: operator name -> (R, 3) rendered deflection (normalised units).
        eps_obs: (R, 3) observed deflection in the same units.
        weights: operator name -> lambda (e.g. lambda_a for ``auto``, lambda_d for ``discrete``).
    """
    return weighted_sum(deflection_terms(eps, eps_obs), weights)


