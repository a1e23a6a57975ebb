"""How every solver is scored, built once from the scene: the errors of a sigma volume against the truth, of
deflections on fixed training rays, and of the held-out views (deflections and, where they are physical, the
image displacements the cameras see).

The solver is not part of it: it is given the solver's ``predict(origins, dirs) -> deflections of sigma``, so
every solver is scored by the same code. What depends only on the data (the fixed ray subsets, the observed
held-out displacements, the PSNR peaks) is computed here once.
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np
import torch

from nerif.data import Scene
from nerif.data.observation import observations
from nerif.metrics import deflection_rmse, explained_share, flame_region, psnr_db, rmse, value_range
from nerif.sensing.interpolation import Interpolation, interpolation
from nerif.sensing.vectors import vector_noise
from nerif.units import DEFLECTION, SIGMA, declare

declare(deflection_rmse=DEFLECTION, deflection_rmse_auto=DEFLECTION, deflection_rmse_discrete=DEFLECTION,
        heldout_deflection_rmse=DEFLECTION, sigma_rmse=SIGMA,
        sigma_relative_error="1 (RMS of sigma - sigma_true over RMS of sigma_true, the whole box)",
        heldout_explained="1 (share of the held-out displacements' mean square the fit explains; 1 perfect, below 0 "
                          "worse than no flame)",
        heldout_photometric_rmse="1 (share of the images' full range)",
        heldout_photometric_rmse_flow="1 (share of the images' full range)",
        heldout_photometric_rmse_none="1 (share of the images' full range)",
        heldout_misfit="px (the held-out displacement RMSE; sigma where there is no temperature)",
        heldout_noise_px="px (what the flow's own noise leaves of a perfect fit of the held-out views: sqrt 2 times "
                         "their vectors' noise)",
        heldout_misfit_over_noise="1 (the held-out displacement RMSE over heldout_noise_px)",
        view_misfit_over_noise="1 (each training view's displacement RMSE over sqrt 2 times its vectors' noise)",
        heldout_image_misfit="1 (share of the images' full range: the held-out image residual, both images band-passed "
                             "and the reference read as the image term compares them)")

UNEXPLAINED = 5.0  # the held-out misfit over the flow's noise beyond which a view is called unexplained (the shared
# captures with their rigs as measured: 1.8-3.5, the fine-pixel lifted flame highest: benchmarks/RESULTS.md, issue 58)
UNSEEN = 3.0  # ... and this many times the training views' median (the shared captures: 1.1-2.8, lifted_fine highest)
CONTRADICTED = 1.5  # a training view explained this many times worse than the median view is called contradicted (the
# shared captures with their rigs as measured: at most 1.16 times the median, benchmarks/RESULTS.md, issue 58)
READ = interpolation("bicubic")  # how heldout_photometric_rmse reads the reference: one reading for every run,
# whatever its data_term.interpolation, so that the figure compares runs (a monitored figure, kept as it was)
Predict = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]  # (R, 3) origins [mm], dirs -> (R, 3) sigma units


def displacement_noise(scene: Scene) -> Optional[np.ndarray]:
    """(V,) what the flow's own noise leaves of a perfect prediction of each view's displacements [px of the full
    sensor]: sqrt 2 (both components) times its vectors' noise (:func:`nerif.sensing.vectors.vector_noise`), NaN for
    a view whose noise cannot be read (too few vectors); None where the displacements were not measured from
    images."""
    if any(view.measured_px is None for view in scene.views):
        return None
    noise = []
    for view in scene.views:
        u = np.asarray(view.measured_px, dtype=np.float64)
        ok = np.isfinite(u).all(-1)
        noise.append(np.sqrt(2.0) * vector_noise(np.where(ok[..., None], u, 0.0), ok))
    return np.where(np.asarray(noise) > 0, noise, np.nan)


def fixed_rays(scene: Scene, per_view: int, seed: int) -> torch.Tensor:
    """Up to ``per_view`` random rays of every view of ``scene`` (scene indices), the same for a given seed."""
    g = torch.Generator().manual_seed(seed)
    counts, starts = scene.view_counts().cpu(), scene.view_start.cpu()
    idx = [s + torch.randperm(int(c), generator=g)[:per_view] for s, c in zip(starts[:-1], counts)]
    return torch.cat(idx).to(scene.dirs.device)


class Evaluation:
    """The scores of a scene's reconstructions.

    Args:
        scene: the training scene, with its held-out views (``scene.heldout``) if any.
        flame_threshold_K: flame region: ``|T_true - T0|`` above it.
        eval_rays_per_view: fixed rays per view on which errors are followed during a run.
        seed: draws the fixed rays (training views with ``seed + 1``, held-out views with ``seed + 2``).

    Attributes:
        train_index: (R,) the fixed training rays (scene indices).
        heldout_index: (R_h,) the fixed held-out rays, or None.
        heldout_displacements: (N_h, 2) observed displacements [px] of every held-out ray where deflections are
            physical, else None.
    """

    def __init__(self, scene: Scene, flame_threshold_K: float, eval_rays_per_view: int, seed: int):
        self.scene, self.flame_threshold_K = scene, float(flame_threshold_K)
        self.train_index = fixed_rays(scene, eval_rays_per_view, seed + 1)
        self.heldout_index, self.heldout_displacements, self.peaks = None, None, {}
        self.heldout_noise_px: Optional[float] = None
        self.view_noise_px = displacement_noise(scene) if self.physical else None
        h = scene.heldout
        if h is not None:
            self.heldout_index = fixed_rays(h, eval_rays_per_view, seed + 2)
            self.peaks["deflection"] = value_range(h.eps)  # PSNR peaks: the range of every observation
            if self.physical:
                self.heldout_displacements = h.displacement_px
                self.peaks["displacement"] = value_range(self.heldout_displacements)
                noise = displacement_noise(h)
                known = None if noise is None else noise[np.isfinite(noise)]
                self.heldout_noise_px = float(known.mean()) if known is not None and known.size else None

    @property
    def physical(self) -> bool:
        """Whether deflections have physical units (radians), so that displacements [px] can be reported."""
        return self.scene.ambient.temperature_known

    def field_errors(self, sigma: np.ndarray) -> dict:
        """Temperature and sigma errors of a sigma volume (nx, ny, nz) against the scene's truth (empty without
        one)."""
        if self.scene.truth_T is None:
            return {}
        amb, Tt = self.scene.ambient, self.scene.truth_T
        T, sigma_true = amb.temperature_from_sigma(sigma), amb.sigma_from_temperature(Tt)
        flame = flame_region(Tt, amb.T0, self.flame_threshold_K)
        norm, sigma_rmse = float(np.sqrt(np.mean(sigma_true**2))), rmse(sigma, sigma_true)
        return {"temperature_rmse_K": rmse(T, Tt),
                "temperature_rmse_flame_K": rmse(T, Tt, flame) if flame.any() else None,  # None: no flame at all
                "sigma_rmse": sigma_rmse,
                "sigma_relative_error": sigma_rmse / norm if norm > 0 else None}  # |s - s_true| / |s_true|

    def train_rays(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Origins and directions (R, 3) of the fixed training rays."""
        s, i = self.scene, self.train_index
        return s.origins[s.ray_views()[i]], s.dirs[i]

    def view_misfits(self, predict: Predict) -> dict:
        """``view_misfit_over_noise``: each training view's displacement RMSE on its fixed rays (``predict``'s, sigma
        units, :meth:`train_rays`) over what the flow's noise leaves it, None for a view whose noise could not be
        read; empty (nothing rendered) where the displacements were not measured from images. A view the others
        contradict (its images swapped with another's, its camera moved) stands out: the field cannot fit it and
        them at once."""
        if self.view_noise_px is None or not np.isfinite(self.view_noise_px).any():
            return {}
        s, i = self.scene, self.train_index
        miss = (s.to_displacement(predict(*self.train_rays()) * s.scale, i) - s.displacement_px[i]).double()
        views = s.ray_views()[i]
        ms = torch.zeros(s.n_views, dtype=torch.float64, device=miss.device).index_add_(0, views, miss.pow(2).sum(-1))
        n = torch.bincount(views, minlength=s.n_views).clamp_min(1)
        ratio = (ms / n).sqrt().cpu().numpy() / self.view_noise_px
        return {"view_misfit_over_noise": [round(float(r), 3) if np.isfinite(r) else None for r in ratio]}

    def deflection_errors(self, predicted: dict) -> dict:
        """``deflection_rmse_<name>`` [rad] of each prediction (name -> (R, 3) sigma units on :meth:`train_rays`)
        against the observations."""
        obs = self.scene.eps[self.train_index]
        return {f"deflection_rmse_{n}": deflection_rmse(e * self.scene.scale, obs) for n, e in predicted.items()}

    def heldout_predictions(self, predict: Predict, index: Optional[torch.Tensor] = None) -> torch.Tensor:
        """(R, 3) predicted deflections [rad] of the held-out rays ``index`` (default: all)."""
        h = self.scene.heldout
        index = torch.arange(len(h.dirs), device=h.dirs.device) if index is None else index
        return predict(h.origins[h.ray_views()[index]], h.dirs[index]) * self.scene.scale

    def heldout_misfit(self, predict: Predict, pred: Optional[torch.Tensor] = None) -> Optional[float]:
        """What a field leaves unexplained of every held-out ray's measurement: the displacement RMSE [px] where
        deflections are physical, else the deflection RMSE (sigma units); None without held-out views (``pred``:
        the predictions of every held-out ray [rad] when already computed). The figure by which a run chooses
        between two of its fields (:class:`~nerif.solvers.neural.NeuralSolver`)."""
        if self.scene.heldout is None:
            return None
        m = self.heldout_errors(predict, every=True, pred=pred, photometric=False)
        return m.get("heldout_displacement_rmse_px", m["heldout_deflection_rmse"])

    def heldout_errors(self, predict: Predict, every: bool = False, pred: Optional[torch.Tensor] = None,
                       photometric: bool = True) -> dict:
        """Errors on the held-out views (empty without any): deflection RMSE [rad] and PSNR [dB] of predicted
        against observed deflections and, where deflections are physical, the same for the image displacements
        [px], and where the scene holds images the photometric residual (``photometric``). On the fixed held-out rays,
        or on ``every`` held-out ray (``pred``: their predictions [rad] when already computed), where also what no
        flame would leave (``_none``) and the share of the held-out displacements the fit explains
        (``heldout_explained``, :func:`nerif.metrics.explained_share`: the quality figure a user without a truth
        can read; near 1 where fit and data agree, falling as the data get noisier or the views disagree, below 0
        for a failed fit)."""
        h = self.scene.heldout
        if h is None:
            return {}
        index = torch.arange(len(h.dirs), device=h.dirs.device) if every else self.heldout_index
        pred = self.heldout_predictions(predict, index) if pred is None else pred
        obs = h.eps[index]
        m = {"heldout_deflection_rmse": deflection_rmse(pred, obs),
             "heldout_psnr_db": psnr_db(pred, obs, self.peaks["deflection"])}
        if self.physical:
            u_pred = h.to_displacement(pred, index)
            u_obs = self.heldout_displacements[index]
            m.update(heldout_displacement_rmse_px=deflection_rmse(u_pred, u_obs),
                     heldout_displacement_psnr_db=psnr_db(u_pred, u_obs, self.peaks["displacement"]))
            if every:  # what no flame at all leaves, and the share of the displacements the fit explains
                none = m["heldout_displacement_rmse_px_none"] = deflection_rmse(torch.zeros_like(u_obs), u_obs)
                if none:
                    m["heldout_explained"] = explained_share(m["heldout_displacement_rmse_px"], none)
                if self.heldout_noise_px:
                    m["heldout_noise_px"] = self.heldout_noise_px
                    m["heldout_misfit_over_noise"] = m["heldout_displacement_rmse_px"] / self.heldout_noise_px
        if photometric and not h.lacks_image_model():
            m["heldout_photometric_rmse"] = self.photometric_rmse(index, pred)
            if every:  # what the flow's displacements and none leave, for comparison
                m["heldout_photometric_rmse_flow"] = self.photometric_rmse(index, obs)
                m["heldout_photometric_rmse_none"] = self.photometric_rmse(index, torch.zeros_like(obs))
        return m

    def photometric_rmse(self, index: torch.Tensor, eps: torch.Tensor, read: Interpolation = READ,
                         highpass_px: Optional[float] = None, lowpass_px: Optional[float] = None) -> float:
        """RMS over the image pixels of held-out rays ``index`` of ``I_ref(x + u) - I_dist(x)`` [image intensity,
        full range 1], ``u`` the displacement of deflections ``eps`` [rad] (R, 3), the same over each ray's block
        of image pixels: how well the deflections explain the held-out images themselves, whatever the flow says.
        The reference read by ``read``; both images band-passed first where ``highpass_px`` or ``lowpass_px`` is
        set (:func:`~nerif.losses.images.bandpass`: as the image term compares them)."""
        h = self.scene.heldout
        views, total, count = h.ray_views()[index], 0.0, 0
        models = observations(h)
        for v in views.unique().tolist():
            sel, view = views == v, models[v]
            u = view.displacement(eps[sel].double() / h.scale, index[sel] - view.rays.start)
            r = view.residual(u, read, view.images(read, highpass_px, lowpass_px), h.pixel[index[sel]])
            total, count = total + float(r.pow(2).sum()), count + r.numel()
        return (total / max(count, 1)) ** 0.5

    def stage_figures(self, predict: Predict, sigma: Callable[[], np.ndarray], term=None) -> dict:
        """What a field leaves of the held-out views, so that two stages' fields can be compared
        (:meth:`nerif.solvers.neural.NeuralSolver.choose_by_heldout`): ``heldout_misfit`` (:meth:`heldout_misfit`),
        where they hold images ``heldout_photometric_rmse`` and, read as the image ``term`` reads them (its
        ``read``, ``highpass_px``, ``lowpass_px``), ``heldout_image_misfit``; every held-out ray rendered once; and
        where a truth is known the errors of the field's ``sigma()`` (:meth:`field_errors`)."""
        h = self.scene.heldout
        index = torch.arange(len(h.dirs), device=h.dirs.device)
        pred = self.heldout_predictions(predict, index)
        out = {"heldout_misfit": self.heldout_misfit(predict, pred)}
        if not h.lacks_image_model():  # the same field against the held-out images themselves
            out["heldout_photometric_rmse"] = self.photometric_rmse(index, pred)
            if getattr(term, "read", None) is not None:  # and as the image term compares them
                out["heldout_image_misfit"] = self.photometric_rmse(index, pred, term.read, term.highpass_px,
                                                                    term.lowpass_px)
        if self.scene.truth_T is not None:
            out.update(self.field_errors(sigma()))
        return out

    @staticmethod
    def contradicted(m: dict) -> str:
        """One sentence naming the training views the fit explains far worse than the others (``view_misfit_over_noise``
        of ``m`` above :data:`CONTRADICTED` times the median of every view's), with the usual causes; else ""."""
        ratios = m.get("view_misfit_over_noise") or []
        if sum(r is not None for r in ratios) < 3:
            return ""
        median = float(np.median([r for r in ratios if r is not None]))
        worse = [v for v, r in enumerate(ratios) if r is not None and r > CONTRADICTED * median]
        if not worse:
            return ""
        return (f"training view(s) {worse} are explained far worse than the others ("
                + ", ".join(f"{ratios[v]:.1f}" for v in worse) + f"x the flow's noise against a median of {median:.1f}x):"
                " the other views contradict them. Usual causes: images listed in the wrong order (two views' images "
                "swapped), a camera moved between the calibration and the capture, a wrong angle in the rig file for "
                "that view; leave it out (data.heldout) to see whether the rest agree")

    @staticmethod
    def unexplained(m: dict) -> str:
        """One sentence where the fit leaves the held-out views' displacements well beyond what the flow's noise
        allows (``heldout_misfit_over_noise`` of ``m`` above :data:`UNEXPLAINED`) and well beyond what it leaves of
        the views it trained on (above :data:`UNSEEN` times their median ``view_misfit_over_noise``: a fit that
        explains none of its views, too short or too coarse, is not a view it did not see), naming the usual causes;
        else ""."""
        ratio = m.get("heldout_misfit_over_noise")
        trained = [r for r in m.get("view_misfit_over_noise") or [] if r is not None]
        trained = float(np.median(trained)) if trained else None
        if ratio is None or not ratio > UNEXPLAINED or (trained is not None and not ratio > UNSEEN * trained):
            return ""
        than = f", {ratio / trained:.1f}x the training views' median" if trained else ""
        return (f"the reconstruction does not explain a view it did not see: the held-out displacements are missed by "
                f"{m['heldout_displacement_rmse_px']:.3g} px RMS, {ratio:.1f}x what the flow's noise leaves "
                f"({m['heldout_noise_px']:.3g} px){than} (the shared captures, their rigs as measured: at most 3.5x "
                "and 2.8x). Usual causes: a camera moved or knocked between the calibration and the capture, two "
                "views' images swapped, a held-out view's angle or distance wrong in the rig file, a flame that "
                "changed between the exposures; look at heldout/*.png")

    @staticmethod
    def failed(m: dict) -> str:
        """One sentence where the held-out views say the fit failed: its prediction explains their images, or their
        displacements, worse than no flame at all would (``heldout_*`` against ``heldout_*_none`` of ``m``, the
        figures of :meth:`heldout_errors` on every held-out ray); else ""."""
        for key, what in (("heldout_photometric_rmse", "images"), ("heldout_displacement_rmse_px", "displacements")):
            fit, none = m.get(key), m.get(f"{key}_none")
            if fit is not None and none is not None and fit > none:
                return (f"the fit failed: it explains the held-out view's {what} worse than no flame at all ({key} "
                        f"{fit:.4g} against {none:.4g}); its temperatures mean nothing. Look at the measurement "
                        "lines of the log (shakes, pixels left out) and at heldout/*.png")
        return ""

    def heldout_images(self, pred: torch.Tensor) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per held-out view, (observed, predicted) on its pixel grid, NaN where it has no ray: displacements
        [px] (height, width, 2) where physical, else deflections (height, width, 3); ``pred``: (N_h, 3)
        predictions [rad] of every held-out ray."""
        h = self.scene.heldout
        obs = self.heldout_displacements if self.physical else h.eps
        pred = h.to_displacement(pred) if self.physical else pred
        out = []
        for v in range(h.n_views):
            sl = h.view_slice(v)
            out.append(tuple(h.view_image(v, x[sl].detach().cpu().double().numpy(), np.nan) for x in (obs, pred)))
        return out
