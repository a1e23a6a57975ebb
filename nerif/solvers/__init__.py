"""Solvers (``SOLVERS``: nerif, cgls), all run by the same loop (:class:`IterativeSolver`)."""
from nerif.solvers.base import SOLVERS, DivergenceError, IterativeSolver

__all__ = ["SOLVERS", "DivergenceError", "IterativeSolver"]
