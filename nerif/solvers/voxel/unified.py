"""Unified BOS tomography (Grauer and Steinberg, Exp. Fluids 2020): the linearised brightness-constancy equation
``grad I_ref(x) . u(x) = I_dist(x) - I_ref(x)``, with ``u = A eps`` and ``eps`` the projector's deflections, as
the voxel solver's linear system, instead of displacements from an optical flow.

Every image pixel of a ray's block (the ``b x b`` image pixels the ray stands for) gives one equation in the
ray's displacement ``u_r``. Their least-squares sum is ``u_r^T G_r u_r - 2 h_r^T u_r + const`` with the block's
structure tensor ``G_r = sum g g^T`` and ``h_r = sum g (I_dist - I_ref)``, that is ``|L_r^T u_r - L_r^-1 h_r|^2``
(``G_r = L_r L_r^T``): two rows per ray instead of ``b^2``, the same solution. Linearised about ``u0`` (zero, as
the paper, or the flow's displacements: then ``I_ref`` and ``g`` are taken at ``x + u0`` and ``h`` gains
``G u0``), which extends it to displacements beyond the texture's linear range.
"""
from __future__ import annotations

import torch

from nerif.data.observation import observations
from nerif.losses.images import cached_photometric_scale
from nerif.sensing.interpolation import Interpolation


def unified_system(scene, highpass_px, linearize_at: str = "zero", step_px: float = 0.01, lowpass_px=None,
                   deflection_units: bool = True, *, read: Interpolation):
    """The unified system of every ray of ``scene``: ``M`` (N, 2, 3) with ``M eps = L^T A eps`` (``eps`` in sigma
    units) and its right-hand side ``c`` (N, 2), in float64 on the scene's device.

    Args:
        scene: a scene with images (:class:`nerif.data.scene.ViewImages`).
        highpass_px, lowpass_px: the images are band-passed as the neural image term's
            (:func:`nerif.losses.images.bandpass`; None: as they are).
        linearize_at: ``zero``, or ``flow``: about the displacements of the scene's observations.
        step_px: the image gradient is the interpolant's, by central differences of this step.
        deflection_units: divide each view's rows by ``b sqrt(photometric_scale)`` (``b^2`` pixels per ray), so
            that a row's squared residual is worth a squared deflection of sigma, as the flow's rows are: a
            regulariser's ``lam`` then weighs the same for both data. In intensity units, on the independent
            capture, a row's squared residual was 0.011 of the deflection's: the flow's bracket of weights was
            about 90x too strong there. False: the pixels' own equations (intensity units).
        read: how the reference is read between its pixels (:mod:`nerif.sensing.interpolation`; the voxel
            solver's: :data:`nerif.solvers.voxel.solver.UNIFIED_READ`).
    """
    lacks = scene.lacks_image_model()
    if lacks:
        hint = ": use data=capture or data.sensing=realistic" if scene.images is None else ""
        raise ValueError(f"solver=cgls data_term=images (unified BOS) needs {lacks}{hint}")
    if linearize_at not in ("zero", "flow"):
        raise ValueError(f"linearize_at must be zero or flow, got '{linearize_at}'")
    b = scene.image_block()
    Ms, cs = [], []
    for view in observations(scene):
        A = view.gain_px  # (n, 2, 3) image px per sigma unit
        images = view.images(read, highpass_px, lowpass_px)
        u0 = view.image_px(scene.displacement_px[view.rays].double()) if linearize_at == "flow" else \
            A.new_zeros(len(A), 2)  # the field's displacement linearised about
        at = u0 + view.shake_px  # ... and the shake, which the images hold
        steps = [at.new_tensor(e) * step_px for e in ((1.0, 0.0), (0.0, 1.0))]
        g = torch.stack([(view.residual(at + e, read, images) - view.residual(at - e, read, images)) / (2 * step_px)
                         for e in steps], -1)  # (n, P, 2) the reference's gradient at x + at
        diff = -view.residual(at, read, images)  # I_dist(x) - I_ref(x + at)
        G = g.transpose(1, 2) @ g  # (n, 2, 2)
        h = (g * diff[..., None]).sum(1) + (G @ u0[..., None])[..., 0]
        G = G + 1e-9 * G.diagonal(dim1=1, dim2=2).sum(-1).mean() * torch.eye(2, dtype=G.dtype, device=G.device)
        L = torch.linalg.cholesky(G)
        unit = b * cached_photometric_scale(images[0], A, read, scene.cache_dir) ** 0.5 if deflection_units else 1.0
        Ms.append(L.transpose(1, 2) @ A / unit)
        cs.append(torch.linalg.solve_triangular(L, h[..., None], upper=False)[..., 0] / unit)
    return torch.cat(Ms), torch.cat(cs)
