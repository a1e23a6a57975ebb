"""Solvers (``SOLVERS``: nerif, cgls), all run by the same loop (:class:`IterativeSolver`)."""
from nerif.solvers.base import SOLVERS, DivergenceError, Interrupted, IterativeSolver

__all__ = ["SOLVERS", "DivergenceError", "Interrupted", "IterativeSolver"]
