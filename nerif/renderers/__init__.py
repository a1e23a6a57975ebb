"""Ray sampling (``SAMPLERS``: uniform, occupancy), gradient operators (``GRADIENTS``: auto, discrete) and
deflection rendering of neural and voxel fields."""
from nerif.renderers.deflection import DeflectionRenderer, integrate, perpendicular, render_deflections
from nerif.renderers.gradients import GRADIENTS
from nerif.renderers.samplers import SAMPLERS, Samples
from nerif.renderers.voxel import gradient_volume, voxel_deflection

__all__ = ["DeflectionRenderer", "GRADIENTS", "SAMPLERS", "Samples", "integrate", "perpendicular", "render_deflections", "gradient_volume",
           "voxel_deflection"]
