"""What the neural field is fitted to (``data_term=``): the deflections the optical flow measured (``flow``), the
background images themselves (``images``), or the images where the data hold them and the flow elsewhere
(``auto``, the default).

A data term draws each iteration's rays (:meth:`draw` -> :class:`RayBatch`) and, given the deflections the
field renders along them (operator name -> (R, 3) sigma units), returns the misfit per operator
(:meth:`terms`), in the unit of a squared deflection of sigma for both, so that the other loss weights mean the
same whichever term is fitted. Once set up it hands the solver its training stages (:meth:`stages`,
:class:`~nerif.solvers.stages.Stage`): what each stretch of the run fits, for how long, at what rate, and whether
the held-out views choose between two stages' fields.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Optional

import numpy as np
import torch

from nerif.data import Scene
from nerif.data.observation import image_displacement, observations
from nerif.losses import deflection_terms
from nerif.losses.images import bandpass, cached_photometric_scale, cell_origin, cell_weights, photometric_residual
from nerif.registry import Registry
from nerif.sensing.interpolation import INTERPOLATIONS, interpolation as interpolation_named
from nerif.sensing.noise import FLOOR as NOISE_FLOOR
from nerif.solvers.batches import RayBatcher
from nerif.solvers.stages import Stage

DATA_TERMS = Registry("data term", package="nerif.solvers")
log = logging.getLogger(__name__)
FLOW_WEIGHT_BLOCK = 4  # image pixels between rays at which the flow term weighs ``flow_weight`` (the shared captures')
MARGIN = 4  # rows of border between views in the image term's stacked images (bicubic reads 2 px around)


@dataclass
class PixelRays:
    """Rays through single image pixels of cells of the ray grid: ``corners`` (C, 4) the scene indices of each
    cell's 2 x 2 rays (top-left, top-right, bottom-left, bottom-right), ``offsets`` (C, 2) [px] (column, row) of the
    pixel from the cell's first pixel and ``weights`` (C, 4) its bilinear weights of the corners
    (:func:`~nerif.losses.images.cell_weights`)."""

    corners: torch.Tensor
    offsets: torch.Tensor
    weights: torch.Tensor

    def between(self, values: torch.Tensor) -> torch.Tensor:
        """(N, ...) per scene ray -> (C, ...) bilinear between each cell's corners, at its pixel."""
        v = values[self.corners]  # (C, 4, ...)
        return (self.weights.to(v.dtype).reshape(*self.weights.shape, *[1] * (v.dim() - 2)) * v).sum(1)


@dataclass
class RayBatch:
    """The rays of one training step: ``origins``, ``dirs`` (R, 3) and ``index`` (R,) their scene indices (of a ray
    through a single pixel, its cell's top-left ray's; ``pixels`` says where it passes)."""

    origins: torch.Tensor
    dirs: torch.Tensor
    index: torch.Tensor
    pixels: Optional[PixelRays] = None


def scene_rays(scene: Scene, index: torch.Tensor) -> RayBatch:
    """The scene's rays ``index`` (R,), with their views' camera centres as origins."""
    views = torch.searchsorted(scene.view_start, index, right=True) - 1
    return RayBatch(scene.origins[views], scene.dirs[index], index)


@DATA_TERMS.register("flow")
class DeflectionTerm:
    """``mean |eps - eps_obs|^2`` over random rays, ``eps_obs`` the scene's observed deflections (the optical
    flow's displacements converted through the rig, or a synthetic scene's own), each ray's weighed by its view's
    noise where the measurement read one (``noise_weighted``, :func:`noise_weights`: the flow's error grows with
    the images' noise)."""

    fitted = "flow"  # what the term fits once set up: flow | images

    def __init__(self, noise_weighted: bool = True):
        self.noise_weighted = bool(noise_weighted)

    def setup(self, scene: Scene, batches: RayBatcher, iterations: int, masks=None) -> "DeflectionTerm":
        self.scene, self.batches, self.iterations = scene, batches, int(iterations)
        self.view_weight = noise_weights(scene) if self.noise_weighted else None  # (V,) or None
        self.ray_weight = (None if self.view_weight is None else  # (N,)
                           self.view_weight.float().to(scene.dirs.device).repeat_interleave(scene.view_counts()))
        return self

    def stages(self) -> list[Stage]:
        """The flow's deflections for the whole run."""
        return [Stage("flow", self, self.iterations)]

    def draw(self, iteration: int) -> RayBatch:
        return scene_rays(self.scene, self.batches(iteration))

    def terms(self, eps: dict, batch: RayBatch, iteration: int) -> dict:
        weight = self.ray_weight[batch.index] if self.ray_weight is not None else None
        return deflection_terms(eps, self.scene.observed[batch.index], weight)

    def for_member(self) -> "DeflectionTerm":
        """A new term, not set up, that an ensemble's member trains on (:meth:`nerif.solvers.neural.NeuralSolver.member`):
        the flow's deflections, noise-weighted as this term's."""
        return DeflectionTerm(self.noise_weighted)

    def parameter_groups(self) -> list[dict]:
        """The term's own parameters, fitted with the field (optimiser groups); none here."""
        return []

    def shakes_px(self) -> Optional[torch.Tensor]:
        """(V, 2) each training view's shake [px of the full sensor] as the fit refined it; None where the term
        refines none."""
        return None

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, st: dict) -> None:
        pass


def noise_weights(scene: Scene) -> Optional[torch.Tensor]:
    """(V,) each view's weight from the noise its measurement read in its images (``noise``; None where it read
    none: the median of the others'; at least :data:`~nerif.sensing.noise.FLOOR`, so that images without noise weigh
    alike): ``1 / sigma_v^2`` over its mean over the views (maximum likelihood: a view
    twice as noisy counts a quarter; views of one noise level count 1 each); None where the scene holds no reading
    (a synthetic scene's deflections)."""
    noise = [f.noise if f.noise and np.isfinite(f.noise) else None for f in scene.findings or ()]
    known = [n for n in noise if n is not None]
    if not known:
        return None
    sigma = torch.tensor([float(np.median(known)) if n is None else n for n in noise], dtype=torch.float64)
    inverse = 1 / sigma.clamp(min=NOISE_FLOOR) ** 2
    return inverse / inverse.mean()


def view_scales(photometric: list[float], weights: Optional[torch.Tensor] = None) -> torch.Tensor:
    """(V,) what one unit of each view's mean squared residual is divided by in the image term: each view's
    :func:`~nerif.losses.images.photometric_scale` ``s_v`` (the residual in the unit of a deflection misfit, every
    view alike), or with noise ``weights`` (:func:`noise_weights`) ``1 / (w_v mean(1 / s))``: the residuals weighed
    as their noise says, the weights summing to what they did, so that the term keeps its size beside the flow
    term (on the shared captures, whose views' ``s_v`` agree within 0.2 %, the same as without)."""
    s = torch.tensor(photometric, dtype=torch.float64)
    return s if weights is None else 1 / (weights * (1 / s).mean())


@DATA_TERMS.register("images")
class ImageTerm(DeflectionTerm):
    """The photometric residual ``I_ref(x + u(x)) - I_dist(x)`` at every image pixel of random patches of the ray
    grid: the field's deflections are rendered at the ``patch x patch`` rays of a patch, turned into displacements
    [image px] through the rig geometry, interpolated bilinearly inside each cell of 2 x 2 rays to its ``b x b``
    image pixels (``b``: rays are ``b`` image pixels apart), and the reference image is read there (the band-limited
    picture through its pixels by default, :mod:`nerif.sensing.interpolation`).
    A patch of k x k rendered rays scores (k - 1)^2 cells: with k = 4, 2.25x the pixels of separate cells for the
    same rendering, and the residual's noise, not its cost, is what limits it. No optical flow enters it,
    except for the flow's stage first: ``flow_warmup`` of ``train.iterations`` fit the flow's deflections to start
    from (the residual is not convex beyond about half the background's texture wavelength), then the images
    refine that field for ``image_iterations`` more, the learning rate's cosine restarted at ``image_lr`` of its
    peak. The held-out views then choose (``choose_by_heldout``): where the images' field does not explain their
    images better than the flow's field did at the end of its stage, the run keeps the flow's
    (:class:`~nerif.solvers.neural.NeuralSolver`), so that images which a camera recorded otherwise than this
    term models them cannot make a run worse than the flow alone.

    Args:
        flow_warmup: share of ``train.iterations`` that fit the flow term first (0: images from the start; 1: the
            whole of them, the flow's own converged run).
        image_iterations: share of ``train.iterations`` that fit the images after the flow's stage; null: the
            rest of them (``1 - flow_warmup``).
        image_lr: the images' stage restarts the cosine learning-rate schedule at this share of ``train.lr``; null:
            one schedule over both stages.
        choose_by_heldout: keep the images' field only where it explains the held-out views' images (as this term
            compares them) better than the flow's field at the end of its stage (false: the images' field always).
        highpass_px: compare the images less their Gaussian blur of this width [px] (a smooth brightness
            change between the exposures, the flame's own light); null: as they are.
        interpolation: how the reference image is read between its pixels (:data:`~nerif.sensing.interpolation.
            INTERPOLATIONS`): ``bandlimited`` (the band-limited picture through its pixels: no gain bias),
            ``bspline`` (the cubic B-spline through them), ``bicubic`` (PyTorch's cubic convolution) or ``bilinear``.
        patch: rays per side of a patch (at least 2); a step draws ``rays_per_batch / patch^2`` patches.
        lowpass_px: blur both images by a Gaussian of this width [px] first (sensor noise); null: none.
        flow_weight: in the images' stage, the flow term on the same rays is added with this weight where rays are
            :data:`FLOW_WEIGHT_BLOCK` image pixels apart, and ``(4 / b)^2`` times it where they are ``b`` apart: the
            images' information grows with the pixels between the rays, the flow's does not (0: images alone).
            It costs no rendering. The images fix the fine structure the flow's window blurs; the flow keeps the
            low-frequency level, which the image fit alone leaves off on the independent captures (why is not
            established: ``benchmarks/RESULTS.md``).
        shake_lr: each view's shake between the exposures (the measurement stage's, :mod:`nerif.sensing.shake`) is
            refined with the field at this learning rate [image px a step] (0: kept as measured): the images hold
            the shake photometrically, where the flow's estimate carries its own bias (:meth:`shakes_px`).
        pixels_per_cell: compare at most this many of each cell's ``b x b`` image pixels a step, drawn afresh
            (:meth:`cell_pixels`); null: all.
        render_at: where the field's deflections are rendered for the images: ``corners``, at the 2 x 2 rays of each
            cell, their displacements interpolated bilinearly to its pixels (a flame sharper than the rays' spacing
            is read smoothed: on the shared bunsen flame the photometric optimum of displacements so interpolated
            from its true ones lies at 1.034x them, 1.009x on the lifted flame), or ``pixels``: each of the step's
            ``rays_per_batch`` rays through one random pixel of a random cell, its direction, displacement matrix
            and flow interpolated from the cell's corner rays (exact for a pinhole camera's directions), and that
            pixel compared: no displacement is interpolated, at a quarter of the pixels a step.
        noise_weighted: weigh each view's residuals, and its flow's, by the noise its measurement read
            (:func:`noise_weights`, :func:`view_scales`); false: every view alike in the unit of a deflection misfit.
    """

    fitted = "images"

    def __init__(self, flow_warmup: float = 1.0, highpass_px: Optional[float] = 8.0, interpolation: str = "bandlimited",
                 patch: int = 2, lowpass_px: Optional[float] = None, flow_weight: float = 1.0, shake_lr: float = 0.0,
                 noise_weighted: bool = True, pixels_per_cell: Optional[int] = 256,
                 image_iterations: Optional[float] = 0.5, image_lr: Optional[float] = 0.2,
                 choose_by_heldout: bool = True, render_at: str = "corners"):
        if not 0.0 <= flow_warmup <= 1.0:
            raise ValueError(f"data_term.flow_warmup={flow_warmup}: a share of train.iterations within [0, 1]")
        if image_iterations is not None and not 0.0 < image_iterations <= 10.0:
            raise ValueError(f"data_term.image_iterations={image_iterations}: a share of train.iterations within "
                             "(0, 10], or null (the rest of them)")
        if image_iterations is None and flow_warmup >= 1.0:
            raise ValueError("data_term.flow_warmup=1 leaves no iteration to the images: set data_term.image_iterations "
                             "(a share of train.iterations after the flow's), or use data_term=flow")
        if image_lr is not None and not 0.0 < image_lr <= 1.0:
            raise ValueError(f"data_term.image_lr={image_lr}: a share of train.lr within (0, 1], or null (one schedule)")
        self.image_share, self.image_lr, self.choose_by_heldout = image_iterations, image_lr, bool(choose_by_heldout)
        if highpass_px is not None and not highpass_px >= 0:
            raise ValueError(f"data_term.highpass_px={highpass_px}: a width in pixels (or null)")
        if interpolation not in INTERPOLATIONS.names():
            raise ValueError(f"data_term.interpolation={interpolation}: not an interpolation nerif has "
                             f"({', '.join(INTERPOLATIONS.names())})")
        if not (isinstance(patch, int) and patch >= 2):
            raise ValueError(f"data_term.patch={patch}: rays per side of a patch, at least 2")
        self.flow_warmup, self.highpass_px, self.k = float(flow_warmup), highpass_px, patch
        self.read = interpolation_named(interpolation)
        if not flow_weight >= 0:
            raise ValueError(f"data_term.flow_weight={flow_weight}: a weight cannot be negative")
        if not shake_lr >= 0:
            raise ValueError(f"data_term.shake_lr={shake_lr}: a learning rate [image px a step], 0 to keep the shakes")
        self.lowpass_px, self.flow_weight, self.shake_lr = lowpass_px, float(flow_weight), float(shake_lr)
        if pixels_per_cell is not None and not (isinstance(pixels_per_cell, int) and pixels_per_cell >= 1):
            raise ValueError(f"data_term.pixels_per_cell={pixels_per_cell}: a number of image pixels (or null: all)")
        self.pixels_per_cell = pixels_per_cell
        if render_at not in ("corners", "pixels"):
            raise ValueError(f"data_term.render_at must be corners or pixels, got '{render_at}'")
        if render_at == "pixels" and patch != 2:  # before the set-up reads every view's images
            raise ValueError("data_term.render_at=pixels renders one ray a cell of 2 x 2 rays: set data_term.patch=2")
        self.at_pixels = render_at == "pixels"
        self.flow = DeflectionTerm(noise_weighted)

    def setup(self, scene: Scene, batches: RayBatcher, iterations: int, masks=None) -> "ImageTerm":
        """The cells of every view, the displacement matrices of every ray, the images to compare; ``batches``
        is the flow term's (its settings and random stream are this term's too)."""
        why = self.unfit(scene)
        if why:
            hint = ": use data=capture or data.sensing=realistic, or data_term=flow" if scene.images is None else ""
            raise ValueError(f"data_term=images needs {why}{hint}")
        self.scene, self.flow_iterations = scene, int(round(self.flow_warmup * iterations))
        rest = iterations - self.flow_iterations
        self.image_iterations = rest if self.image_share is None else max(1, int(round(self.image_share * iterations)))
        self.flow.setup(scene, batches, iterations)
        device = scene.dirs.device
        b, H = scene.image_block(), scene.images[0].reference.shape[0]
        k = self.k
        patch = torch.full((len(scene.dirs), k * k), -1, dtype=torch.long, device=device)  # rays of each patch
        gain, scale, refs, dists = [], [], [], []
        self.observations = observations(scene)
        for v, (cam, view) in enumerate(zip(scene.cameras, self.observations)):
            sl = scene.view_slice(v)
            pixel = scene.pixel[sl]
            lut = torch.full((cam.height * cam.width,), -1, dtype=torch.long, device=device)
            lut[pixel] = torch.arange(sl.start, sl.stop, device=device)
            col, row = pixel % cam.width, torch.div(pixel, cam.width, rounding_mode="floor")
            for j in range(k * k):  # the k x k rays from this one right- and downwards, row-major
                dr, dc = divmod(j, k)
                inside = (col + dc < cam.width) & (row + dr < cam.height)
                patch[sl][inside, j] = lut[(pixel + dr * cam.width + dc)[inside]]
            A = view.gain_px  # image px per unit of sigma
            ref = self.read.grid(bandpass(view.reference, self.highpass_px, self.lowpass_px))
            gain.append(A.float())
            scale.append(cached_photometric_scale(ref, A, self.read, scene.cache_dir))
            # the views one above the other, MARGIN rows of border between them (factor times as many on a finer
            # grid): one sampling call per step
            pad = self.read.factor * MARGIN
            refs.append(torch.nn.functional.pad(ref[None, None], (0, 0, pad, pad), mode="replicate")[0, 0])
            dists.append(torch.nn.functional.pad(bandpass(view.distorted, self.highpass_px, self.lowpass_px)[None, None],
                                                 (0, 0, MARGIN, MARGIN), mode="replicate")[0, 0])
        self.b, self.rows = b, H + 2 * MARGIN
        # the images' information grows with the pixels a cell holds, the flow's does not
        self.flow_share = self.flow_weight * (FLOW_WEIGHT_BLOCK / b) ** 2
        self.gain = torch.cat(gain)  # (N, 2, 3) per ray
        # what a unit of each view's squared residual is worth (:func:`view_scales`), per ray (N,)
        self.scale = view_scales(scale, self.flow.view_weight).float().to(device).repeat_interleave(scene.view_counts())
        # each view's shake between the exposures, which the images hold and the field does not [image px]
        self.shake = torch.stack([view.shake_px for view in self.observations]).float()
        self.shake_correction = torch.zeros_like(self.shake, requires_grad=self.shake_lr > 0)  # fitted with the field
        self.reference, self.distorted = torch.cat(refs), torch.cat(dists)  # (V f (H + 2 MARGIN), f W), (V (H + 2 MARGIN), W)
        self.weights, self.pixel_offsets = cell_weights(b, torch.float32, device)
        self.patch = patch
        allowed = (patch >= 0).all(-1)
        cells = batches.rays_per_batch if self.at_pixels else max(1, batches.rays_per_batch // (k * k))
        self.batches = RayBatcher(scene, masks.inside if masks is not None else None, cells,
                                  batches.views_per_batch, batches.outside_fraction, batches.generator, allowed)
        return self

    @staticmethod
    def unfit(scene: Scene) -> str:
        """What the scene lacks for this term ("" when nothing): its background images, or rays a whole number (at
        least 2, the same for every view) of image pixels apart on images of one size."""
        return scene.lacks_image_model(min_block=2, one_size=True)

    def stages(self) -> list[Stage]:
        """The flow's deflections for ``flow_iterations`` (:attr:`flow`), then the images for ``image_iterations``
        from ``image_lr`` of the peak rate (the images first and alone: from the peak), the held-out views choosing
        between the two stages' fields (``choose_by_heldout``)."""
        if self.fitted == "flow":
            return self.flow.stages()
        warm = self.flow_iterations > 0
        return [Stage("flow", self.flow, self.flow_iterations),
                Stage("images", self, self.image_iterations, lr=self.image_lr if warm else 1.0,
                      choose=warm and self.choose_by_heldout)]

    def draw(self, iteration: int) -> RayBatch:
        if not self.at_pixels:
            return scene_rays(self.scene, self.patch[self.batches(iteration)].reshape(-1))
        corners = self.patch[self.batches(iteration)]  # (C, 4)
        offsets, weights = self.cell_pixels(len(corners), 1)
        pixels = PixelRays(corners, offsets[:, 0], weights[:, 0])
        rays = scene_rays(self.scene, corners[:, 0].contiguous())
        dirs = torch.nn.functional.normalize(pixels.between(self.scene.dirs), dim=-1)
        return RayBatch(rays.origins, dirs, rays.index, pixels)

    def terms(self, eps: dict, batch: RayBatch, iteration: int) -> dict:
        if batch.pixels is not None:
            return self.pixel_terms(eps, batch)
        s, k = self.scene, self.k

        def cells(a: torch.Tensor) -> torch.Tensor:  # (P k k, ...) per ray -> (C, 4, ...) per cell, its corners
            a = a.reshape(-1, k, k, *a.shape[1:])
            corners = (a[:, :-1, :-1], a[:, :-1, 1:], a[:, 1:, :-1], a[:, 1:, 1:])
            return torch.stack(corners, 3).reshape(-1, 4, *a.shape[3:])

        index = cells(batch.index)
        top = index[:, 0].contiguous()
        views = torch.searchsorted(s.view_start, top, right=True) - 1
        x = cell_origin(s.pixel[top], s.cameras[0].width, self.b)
        x[:, 1] += views * self.rows + MARGIN  # the view's place in the stacked images
        offsets, weights = self.cell_pixels(len(top))
        x = (x[:, None, :] + offsets).reshape(-1, 2)
        A = self.gain[batch.index]  # (R, 2, 3)
        ray_views = torch.searchsorted(s.view_start, batch.index, right=True) - 1
        shake = (self.shake + self.shake_correction)[ray_views]  # (R, 2): each ray's view's
        out = {}
        for name, e in eps.items():
            u = cells(image_displacement(A, e, shake))  # (C, 4, 2) [image px]
            u = torch.einsum("cpk,ckd->cpd", weights.to(u.dtype), u)
            r = photometric_residual(self.reference, self.distorted, x, u.reshape(-1, 2), self.read)
            out[name] = (r.reshape(len(top), -1).pow(2).mean(-1) / self.scale[top]).mean()
        if self.flow_weight > 0:
            flow = self.flow.terms(eps, batch, iteration)
            out = {name: out[name] + self.flow_share * flow[name] for name in out}
        return out

    def pixel_terms(self, eps: dict, batch: RayBatch) -> dict:
        """The residual at each ray's own pixel (``render_at=pixels``), and the flow term at the same rays, their
        observations interpolated between the cell's corner rays."""
        s, px = self.scene, batch.pixels
        top = px.corners[:, 0].contiguous()
        views = torch.searchsorted(s.view_start, top, right=True) - 1
        x = cell_origin(s.pixel[top], s.cameras[0].width, self.b) + px.offsets.long()
        x[:, 1] += views * self.rows + MARGIN  # the view's place in the stacked images
        A = px.between(self.gain)  # (C, 2, 3)
        shake = (self.shake + self.shake_correction)[views]
        out = {}
        for name, e in eps.items():
            u = image_displacement(A, e, shake)
            r = photometric_residual(self.reference, self.distorted, x, u, self.read)
            out[name] = (r.pow(2) / self.scale[top]).mean()
        if self.flow_weight > 0:
            weight = self.flow.ray_weight[top] if self.flow.ray_weight is not None else None
            flow = deflection_terms(eps, px.between(s.observed), weight)
            out = {name: out[name] + self.flow_share * flow[name] for name in out}
        return out

    def cell_pixels(self, n_cells: int, per_cell: Optional[int] = None) -> tuple[torch.Tensor, torch.Tensor]:
        """The image pixels a step compares in each of its ``n_cells`` cells: all ``b x b``, or where there are
        more than ``per_cell`` (default ``pixels_per_cell``), that many drawn afresh for each cell and step (every
        pixel is compared over the steps; a step's cost stays that of ``pixels_per_cell``, however many pixels a ray
        spans). Returns (n_cells, P, 2) their offsets [px] from the cell's first pixel and (n_cells, P, 4) their
        corner weights (:func:`~nerif.losses.images.cell_weights`)."""
        m = self.pixels_per_cell if per_cell is None else per_cell
        if m is None or m >= len(self.weights):
            return (self.pixel_offsets.expand(n_cells, -1, -1), self.weights.expand(n_cells, -1, -1))
        pick = torch.rand((n_cells, len(self.weights)), generator=self.batches.generator,
                          device=self.weights.device).argsort(-1)[:, :m]
        return self.pixel_offsets[pick], self.weights[pick]

    def for_member(self) -> DeflectionTerm:
        """The flow's own term (:meth:`DeflectionTerm.for_member`): members train on the observed deflections."""
        return self.flow.for_member()

    def parameter_groups(self) -> list[dict]:
        """The views' shake corrections [image px], at ``shake_lr``, without weight decay."""
        if not self.refines:
            return []
        return [{"params": [self.shake_correction], "lr": self.shake_lr, "weight_decay": 0.0}]

    @property
    def refines(self) -> bool:
        """Whether the shakes are refined: a rate is set and the images are fitted."""
        return bool(self.shake_lr) and self.fitted == "images"

    def shakes_px(self) -> Optional[torch.Tensor]:
        if not self.refines:
            return None
        shakes = (self.shake + self.shake_correction.detach()).double()
        return torch.stack([view.sensor_px(s) for view, s in zip(self.observations, shakes)]).cpu()

    def state_dict(self) -> dict:
        return {"shake_correction": self.shake_correction.detach().clone()} if self.refines else {}

    def load_state_dict(self, st: dict) -> None:
        if self.refines and "shake_correction" in st:
            with torch.no_grad():
                self.shake_correction.copy_(st["shake_correction"])


@DATA_TERMS.register("auto")
class ImagesWhereGiven(ImageTerm):
    """:class:`ImageTerm` where the scene holds its background images (``data=capture``,
    ``data.sensing=realistic``) with rays at least 2 image pixels apart; :class:`DeflectionTerm` throughout where it
    does not (a synthetic scene's ideal deflections, the paper's deflection PNGs, rays at every image pixel), with
    the reason logged. :attr:`fitted` says which."""

    def setup(self, scene: Scene, batches: RayBatcher, iterations: int, masks=None) -> "ImagesWhereGiven":
        why = self.unfit(scene)
        if not why:
            return super().setup(scene, batches, iterations, masks)
        log.info("data_term=auto fits the flow's deflections: data_term=images would need %s", why)
        self.fitted, self.scene, self.flow_iterations = "flow", scene, iterations
        self.flow.setup(scene, batches, iterations)
        return self
