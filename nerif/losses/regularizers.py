"""Terms on the field itself: the ambient boundary condition that fixes the field's constant, and total
variation."""
from __future__ import annotations

from typing import Optional, Sequence

import torch

from nerif.geometry import ProbeBox, box_faces

class AmbientBoundary:
    """``weight * mean |sigma|`` at random points on the box faces that lie in ambient gas.

    Deflections see only gradients: a constant added to sigma inside the box changes no ray, so nothing in
    the data fixes the ambient level. BOS tomography closes the problem with a Dirichlet condition, n = n0
    on the boundary; this is its soft form. The L1 norm lets a few points where a flame does touch a face
    stay hot instead of biasing the level.

    Args:
        box: the probe box.
        faces: the ambient faces, e.g. ``("x", "z", "-y")`` for the lateral faces and the bottom of a flame
            burning along y (``x``: both faces of that axis; see :func:`nerif.geometry.box_faces`). Empty: no
            condition.
        weight: loss weight (normalised units, beside the deflection MSE).
        points: face points per iteration.
    """

    def __init__(self, box: ProbeBox, faces: Sequence[str] = ("x",), weight: float = 0.05, points: int = 256):
        self.box, self.faces, self.weight, self.points = box, box_faces(faces), float(weight), int(points)
        self._faces = {}  # device -> (F, 2) tensor of the faces, made once (a host-to-device copy waits on a GPU)

    @property
    def active(self) -> bool:
        return bool(self.faces) and self.weight > 0 and self.points > 0

    def sample(self, generator: Optional[torch.Generator], device) -> torch.Tensor:
        """(points, 3) points uniform on each ambient face, the faces drawn evenly [mm]."""
        g = torch.rand(self.points, 3, generator=generator, device=device) * 2 - 1
        if device not in self._faces:
            self._faces[device] = torch.as_tensor(self.faces, device=device)
        faces = self._faces[device][torch.randint(len(self.faces), (self.points,), generator=generator, device=device)]
        g[torch.arange(self.points, device=device), faces[:, 0]] = faces[:, 1].to(g.dtype)
        return self.box.from_grid(g)

    def __call__(self, field, generator: Optional[torch.Generator] = None) -> torch.Tensor:
        device = next(field.parameters()).device
        return self.weight * field(self.sample(generator, device)).abs().mean()


class TotalVariation:
    """``weight * s * h * mean |grad sigma|`` at random points of the box: total variation of the field, the
    regulariser of TV voxel solvers, for the null space that a few views leave (structure at the finest scales
    that no ray sees, which a hash grid otherwise fills with noise).

    The gradient is by forward differences of step ``h`` (the probe grid's voxel: the scale the field is read at).
    ``s`` is the RMS observed deflection, so that ``weight`` is dimensionless: with sigma scaled by c the
    deflection misfit and this term both scale by c^2, and one weight serves flames of any strength.

    Args:
        box: the probe box (points uniform in it; ``h`` = its voxel).
        weight: dimensionless weight (0: off).
        points: random points per iteration.
        scale: ``s``, the RMS magnitude of the observed deflections (normalised units).
        eps: smoothing of the change of sigma over a voxel near 0, relative to ``s``.
    """

    def __init__(self, box: ProbeBox, weight: float, points: int, scale: float, eps: float = 1e-3):
        if weight < 0:
            raise ValueError(f"loss.tv_weight={weight}: a regularisation weight cannot be negative")
        self.box, self.weight, self.points, self.scale = box, float(weight), int(points), float(scale)
        self.h = float(box.voxel_mm)
        self.eps = eps * self.scale

    @property
    def active(self) -> bool:
        return self.weight > 0 and self.points > 0 and self.scale > 0

    def __call__(self, field, generator: Optional[torch.Generator] = None) -> torch.Tensor:
        device = next(field.parameters()).device
        p = self.box.from_grid(torch.rand(self.points, 3, generator=generator, device=device) * 2 - 1)
        steps = torch.cat([torch.zeros(1, 3, device=device), torch.eye(3, device=device) * self.h])
        s = field((p[:, None] + steps).reshape(-1, 3)).reshape(self.points, 4)
        dsigma = s[:, 1:] - s[:, :1]  # sigma change over one voxel along x, y, z
        return self.weight * self.scale * torch.sqrt((dsigma**2).sum(-1) + self.eps**2).mean()
