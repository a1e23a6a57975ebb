"""The classical voxel baseline: a matrix-free projector pair (Ax, Atb) and CGLS solvers that use it."""
from nerif.baselines.cgls import CGLS, REGULARIZERS
from nerif.baselines.projector import PROJECTORS, SparseProjector, VoxelProjector

__all__ = ["CGLS", "PROJECTORS", "REGULARIZERS", "SparseProjector", "VoxelProjector"]
