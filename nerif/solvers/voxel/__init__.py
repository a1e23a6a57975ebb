"""The classical voxel baseline: a projector pair (``Ax``, ``Atb``: ``PROJECTORS``), CGLS with its regularisers
(``REGULARIZERS``) that only uses that pair, and the solver that runs it on a scene (``solver=cgls``)."""
from nerif.solvers.voxel.cgls import CGLS, REGULARIZERS
from nerif.solvers.voxel.projector import PROJECTORS, SparseProjector, VoxelProjector
from nerif.solvers.voxel.solver import CGLSSolver

__all__ = ["CGLS", "CGLSSolver", "PROJECTORS", "REGULARIZERS", "SparseProjector", "VoxelProjector"]
