"""The views' poses (``poses=``): the rig's as given, or refined by the data.

A rig measured by hand is off by a degree here and a few millimetres there, and no setting of the solver gives the
accuracy back. ``refined`` (:class:`RefinedPoses`) corrects each training view's pose by a small rigid offset, a
rotation about the probe centre and a translation, fitted to the view's deflections through the field trained so
far, a few times during the run (bundle adjustment alternating with the field's training): view ``v``'s rays
``(o, d)`` become ``(R_v o + t_v, R_v d)``, and the deflections rendered along them are turned back by ``R_v^T``
into the frame in which its camera measured them.

Why alternate rather than learn the offsets with the field at every step (BARF): a step draws a few dozen rays of
each view, whose gradient moves a pose by noise as much as by signal (on Phantom 5 the field's error doubled on the
true rig), and the positions' gradient through the hash tables costs 3.5-4.6x a step. A fit of each view's five numbers
to hundreds of its rays through the averaged field is precise, and costs a few steps' worth.

The gauge: moving every camera by one rigid motion moves the field with it and changes nothing the data see, so the
offsets are kept of zero mean over the training views (the field stays in the mean frame of the rig as given). A
view is known by its camera centre: a ray that starts at no training camera's centre (a held-out view's) is rendered
as given.
"""
from __future__ import annotations

import logging
import math
from typing import Callable, Optional, Sequence

import numpy as np
import torch

from nerif.geometry import rig_axis
from nerif.registry import Registry
from nerif.units import declare

declare(pose_angle_deg="deg", pose_rotation_deg="deg", pose_translation_mm="mm", pose_rotation_max_deg="deg",
        pose_translation_max_mm="mm", pose_angle_std_deg="deg", pose_refinements="fits",
        text=("poses", "pose_warning"))

log = logging.getLogger(__name__)
POSES = Registry("poses", package="nerif.solvers")
STEP_RAD, STEP_MM = math.radians(0.05), 0.05  # the finite differences of a pose's five numbers
COMPONENTS = {"turn": (0,), "tilt": (1, 2), "shift": (3, 4)}  # a pose's five numbers, as a rig's errors come


def rotation_matrices(omega: torch.Tensor) -> torch.Tensor:
    """(V, 3) rotation vectors [rad] -> (V, 3, 3) rotation matrices (Rodrigues' formula, exact at zero)."""
    theta2 = (omega * omega).sum(-1)[:, None, None]
    K = omega.new_zeros(len(omega), 3, 3)
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -omega[:, 2], omega[:, 1], -omega[:, 0]
    K = K - K.transpose(1, 2)
    small = theta2 < 1e-8
    theta = theta2.clamp_min(1e-8).sqrt()
    a = torch.where(small, 1.0 - theta2 / 6.0, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24.0, (1.0 - torch.cos(theta)) / theta2.clamp_min(1e-8))
    eye = torch.eye(3, dtype=omega.dtype, device=omega.device).expand_as(K)
    return eye + a * K + b * (K @ K)


@POSES.register("given")
class GivenPoses:
    """The rig's poses as given: rays rendered as they are."""

    def setup(self, scene, iterations: int) -> "GivenPoses":
        return self

    def rays(self, origins: torch.Tensor, dirs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, None]:
        """Rays (R, 3) as given, and no turn to undo."""
        return origins, dirs, None

    def back(self, eps: dict, turn) -> dict:
        return eps

    def due(self, iteration: int) -> bool:
        return False

    def report(self) -> dict:
        return {}

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, st: dict) -> None:
        pass


@POSES.register("refined")
class RefinedPoses(GivenPoses):
    """Each training view's rotation about the probe centre and translation, fitted to its deflections through the
    field at ``at`` shares of the run's iterations.

    A view's five numbers: its turn about the rig's axis (:func:`nerif.geometry.rig_axis`, a rotating burner's
    vertical), its two tilts (about the perpendicular axes) and its shift across its line of sight. The field, fitted
    to every view at once, absorbs part of each view's error, so a fit finds part of it (a third to a half on the
    shared two-jet flames turned by +-4 degrees): the fits come often (eight), and a view once found off stays free.

    Args:
        at: the shares of the iterations after which the poses are fitted (each fit: ``steps`` Levenberg-Marquardt
            steps of every view's chosen numbers, the field held).
        components: which numbers are fitted: ``turn``, ``tilt``, ``shift``. The tilts are left out by default: the
            flames' smooth vertical structure hardly pins them, and left free they wander by 1-2 degrees on a true
            rig (the field's error 1.04-1.07x), while a rig measured by hand errs in its turns.
        steps: Levenberg-Marquardt steps of each fit.
        rays_per_view: the rays each view's fit uses, drawn once, in proportion to their observed deflection (the
            rays that see the flame say where it is).
        damping: Levenberg-Marquardt's, a share of each normal matrix's diagonal.
        min_gain: a view's pose first moves where its move explains at least this share of its misfit, and is
            fitted freely from then on; a smaller gain is what the field's own error lends to any pose (on the true
            rigs of the shared bunsen flame and two-jet flames family-111 and -113, at most 0.061, 0.082 and 0.044
            over eight fits of turn and shift; views turned by 2-4 degrees, 0.06-0.34 at the first fit, the larger
            share above 0.1; a turn of a degree is lent as much by the field's error and is not told from it).
        bound_deg, bound_mm: the largest offset of each component: a refinement corrects a rig measured by hand, not
            one that is wrong (a wrong sign or order of the angles).
        min_views: fewer training views than this cannot pin each one's pose against the others: refused.
        seed: the rays' draw.
    Attributes:
        omega: (V, 3) rotation vectors [rad]. t: (V, 3) translations [mm]. angle_std: (V,) the standard error of
            each view's turn about the vertical axis at the last fit [rad].
    """

    def __init__(self, at=(0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8), components=("turn", "shift"), steps: int = 2,
                 rays_per_view: int = 256, damping: float = 0.01, min_gain: float = 0.1, bound_deg: float = 6.0,
                 bound_mm: float = 20.0, min_views: int = 4, seed: int = 0):
        def number(v, whole: bool = False) -> bool:
            ok = isinstance(v, int) if whole else isinstance(v, (int, float))
            return ok and not isinstance(v, bool) and math.isfinite(v)

        def key(name: str, value, what: str, ok: bool) -> None:
            if not ok:
                raise ValueError(f"poses.{name}={value!r}: {what}")

        shares = [at] if number(at) else list(at) if isinstance(at, Sequence) and not isinstance(at, str) else None
        key("at", at, "shares of the run's iterations, each within (0, 1), e.g. [0.25, 0.5, 0.75]",
            bool(shares) and all(number(a) and 0.0 < a < 1.0 for a in shares))
        for name, v in (("steps", steps), ("min_views", min_views)):
            key(name, v, "a whole number of at least 2" if name == "min_views" else "a whole number of at least 1",
                number(v, whole=True) and v >= (2 if name == "min_views" else 1))
        key("rays_per_view", rays_per_view, "a whole number of at least 8", number(rays_per_view, True) and rays_per_view >= 8)
        for name, v in (("bound_deg", bound_deg), ("bound_mm", bound_mm), ("damping", damping)):
            key(name, v, "a positive number", number(v) and v > 0)
        key("min_gain", min_gain, "a share of a view's misfit within [0, 1)", number(min_gain) and 0 <= min_gain < 1)
        key("seed", seed, "a whole number", number(seed, whole=True))
        chosen = [components] if isinstance(components, str) else components
        key("components", components, f"a non-empty list of {', '.join(COMPONENTS)}, e.g. [turn, shift]",
            isinstance(chosen, Sequence) and bool(chosen) and all(c in COMPONENTS for c in chosen))
        self.columns = sorted({k for c in chosen for k in COMPONENTS[c]})
        self.at = tuple(float(a) for a in shares)
        self.steps, self.rays_per_view, self.damping = steps, rays_per_view, float(damping)
        self.min_gain = float(min_gain)
        self.bound_rad, self.bound_mm = math.radians(bound_deg), float(bound_mm)
        self.min_views, self.seed = min_views, seed
        self.moved = False  # whether any offset is not zero (kept here: reading the tensors waits for the device)
        self.fits = 0

    def setup(self, scene, iterations: int) -> "RefinedPoses":
        """Offsets of zero for each of the scene's (training) views; the rays each view's fit uses; the iterations
        after which the fits come."""
        V = scene.n_views
        if V < self.min_views:
            raise ValueError(f"poses=refined: {V} training view(s) cannot pin each view's pose against the others "
                             f"(at least {self.min_views}); use poses=given")
        device = scene.origins.device
        self.centres = scene.origins.detach().clone()  # (V, 3) [mm]: how a ray's view is known
        self.omega = torch.zeros(V, 3, dtype=torch.float64, device=device)
        self.t = torch.zeros(V, 3, dtype=torch.float64, device=device)
        self.angle_std = torch.full((V,), float("nan"), dtype=torch.float64)
        self.free = torch.zeros(V, dtype=torch.bool)  # the views found off, fitted freely since
        axis = rig_axis(scene.cameras)
        tilts = np.linalg.svd(np.eye(3) - np.outer(axis, axis))[0][:, :2].T  # (2, 3) the axes perpendicular to it
        self.turns = torch.as_tensor(np.vstack([axis, tilts]), dtype=torch.float64, device=device)  # (3, 3)
        self.when = sorted({max(1, round(a * iterations)) for a in self.at})
        g = torch.Generator().manual_seed(self.seed)
        weight = scene.observed.norm(dim=-1).double().cpu() + 1e-12
        axes = torch.stack([torch.as_tensor(np.asarray(c.rotation, dtype=np.float64)[:, :2].T) for c in scene.cameras])
        self.across = axes.to(device)  # (V, 2, 3): each camera's image right and down in the world
        self.index = torch.cat([s + torch.multinomial(weight[s:e], min(self.rays_per_view, e - s), generator=g)
                                for s, e in zip(scene.view_start[:-1].tolist(), scene.view_start[1:].tolist()) if e > s])
        self.scene = scene
        return self

    def due(self, iteration: int) -> bool:
        """Whether the poses are fitted after ``iteration`` steps."""
        return iteration in self.when

    def views_of(self, origins: torch.Tensor) -> torch.Tensor:
        """(R, 3) ray origins -> (R,) the training view whose camera centre each starts at, -1 for none."""
        d2 = (origins[:, None, :].float() - self.centres[None].float()).pow(2).sum(-1)  # (R, V)
        nearest = d2.min(-1)
        return torch.where(nearest.values < 1e-4, nearest.indices, torch.full_like(nearest.indices, -1))

    @staticmethod
    def _move(origins, dirs, view, R, shift):
        """Rays (R, 3) of ``view`` (-1: none) moved by the views' rotations R (V, 3, 3) and shifts (V, 3), in their
        dtype; and each ray's rotation (the identity where it belongs to no view)."""
        known = (view >= 0)[:, None, None]
        R = torch.where(known, R[view.clamp_min(0)], torch.eye(3, dtype=R.dtype, device=R.device))
        shift = torch.where(known[..., 0], shift[view.clamp_min(0)], torch.zeros_like(shift[:1]))
        o = (R @ origins.to(R.dtype)[..., None])[..., 0] + shift
        return o.to(origins.dtype), (R @ dirs.to(R.dtype)[..., None])[..., 0].to(dirs.dtype), R

    def rays(self, origins: torch.Tensor, dirs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, Optional[torch.Tensor]]:
        """Rays (R, 3) of the training views moved by their offsets, and (R, 3, 3) each ray's rotation (the identity
        for a ray of no training view); the rays as given and None while every offset is zero."""
        if not self.moved:
            return origins, dirs, None
        return self._move(origins, dirs, self.views_of(origins), rotation_matrices(self.omega).float(), self.t.float())

    def back(self, eps: dict, turn: Optional[torch.Tensor]) -> dict:
        """Deflections (R, 3) rendered along moved rays -> in the frame their cameras measured them (``R^T``)."""
        if turn is None:
            return eps
        return {k: (turn.transpose(1, 2).to(v.dtype) @ v[..., None])[..., 0] for k, v in eps.items()}

    def fit(self, render: Callable[[torch.Tensor, torch.Tensor], torch.Tensor]) -> None:
        """Every view's offsets fitted to its rays' observed deflections through ``render`` ((R, 3) origins and
        directions -> (R, 3) deflections of sigma, the field held): ``steps`` Levenberg-Marquardt steps
        (:meth:`_step`), each followed by the gauge (the mean offset taken off) and the bounds."""
        sc, idx = self.scene, self.index.to(self.scene.dirs.device)
        view = torch.searchsorted(sc.view_start, idx, right=True) - 1
        o0, d0, observed = sc.origins[view], sc.dirs[idx], sc.observed[idx].double()

        def predicted(omega, t):  # (V, 3) offsets -> (R, 3) the chosen rays' deflections, as their cameras see them
            o, d, R = self._move(o0, d0, view, rotation_matrices(omega), t)
            return self.back({"eps": render(o, d).double()}, R)["eps"]

        for _ in range(self.steps):
            omega, t = self._step(predicted, observed, view)
            self.omega = (omega - omega.mean(0)).clamp(-self.bound_rad, self.bound_rad)
            self.t = (t - t.mean(0)).clamp(-self.bound_mm, self.bound_mm)
        self.fits += 1
        self.moved = bool(self.omega.any() or self.t.any())  # once a fit, not every step

    def _step(self, predicted: Callable, observed: torch.Tensor, view: torch.Tensor) -> tuple:
        """One Levenberg-Marquardt step of each view's chosen numbers (of five: its turn, two tilts and its shift
        across its axis; along it, a shift only magnifies the view by a part in a hundred and is left alone) on
        Jacobians of finite differences, all views at once (a view's rays depend on its own pose only). A view
        moves once its move explains :attr:`min_gain` of its misfit, and freely from then on. Returns the new (V, 3)
        rotations and translations."""
        V = len(self.omega)

        def per_view(x: torch.Tensor) -> torch.Tensor:  # (R, ...) -> (V, ...) summed over each view's rays
            return x.new_zeros(V, *x.shape[1:]).index_add_(0, view, x)

        def moved(k: int, size: float):  # the offsets with number k stepped by size
            if k < 3:
                return self.omega + size * self.turns[k], self.t
            return self.omega, self.t + size * self.across[:, k - 3]

        base = predicted(self.omega, self.t)
        J = torch.stack([(predicted(*moved(k, STEP_RAD if k < 3 else STEP_MM)) - base) / (STEP_RAD if k < 3 else STEP_MM)
                         for k in self.columns], -1)  # (R, 3, K)
        r = observed - base  # (R, 3)
        JtJ, Jtr = per_view(J.transpose(1, 2) @ J), per_view((J.transpose(1, 2) @ r[..., None])[..., 0])
        diag = torch.diagonal(JtJ, dim1=1, dim2=2)
        A = JtJ + torch.diag_embed(self.damping * diag + 1e-12 * diag.mean(-1, keepdim=True) + 1e-30)
        delta = torch.linalg.solve(A, Jtr)  # (V, K)
        before = per_view(r.pow(2).sum(-1))
        gain = 1.0 - per_view((r - (J @ delta[view][..., None])[..., 0]).pow(2).sum(-1)) / before.clamp_min(1e-300)
        log.debug("pose fit %d: each view's misfit explained by its move %s", self.fits, gain.cpu().numpy())
        self.free |= (gain >= self.min_gain).cpu()
        delta = torch.where(self.free.to(delta.device)[:, None], delta, torch.zeros_like(delta))
        n = torch.bincount(view, minlength=V).double()
        if 0 in self.columns:  # the turn's standard error
            dof = (3 * n - len(self.columns)).clamp_min(1)
            self.angle_std = (torch.linalg.inv(A)[:, 0, 0] * before / dof).clamp_min(0).sqrt().cpu()
        full = delta.new_zeros(V, 5)
        full[:, self.columns] = delta
        return self.omega + full[:, :3] @ self.turns, self.t + (full[:, 3:, None] * self.across).sum(1)

    def report(self) -> dict:
        """Per view: ``pose_angle_deg`` (its turn about the rig's axis, a rotating burner's vertical), its standard
        error ``pose_angle_std_deg``, ``pose_rotation_deg`` (the rotation vector) and ``pose_translation_mm``; the
        largest sizes; and ``pose_warning`` where an offset stands at its bound (the rig is off by more than a
        refinement corrects)."""
        rot = np.degrees(self.omega.cpu().numpy())
        t = self.t.cpu().numpy()
        turn = rot @ self.turns[0].cpu().numpy()
        out = {"poses": "refined", "pose_refinements": self.fits,
               "pose_angle_deg": [round(float(a), 4) for a in turn],
               "pose_angle_std_deg": [None if not np.isfinite(a) else round(float(a), 4)
                                      for a in np.degrees(self.angle_std.numpy())],
               "pose_rotation_deg": np.round(rot, 4).tolist(), "pose_translation_mm": np.round(t, 3).tolist(),
               "pose_rotation_max_deg": float(np.abs(rot).max()), "pose_translation_max_mm": float(np.abs(t).max())}
        at_bound = [v for v in range(len(rot)) if (np.abs(np.radians(rot[v])) > 0.99 * self.bound_rad).any()
                    or (np.abs(t[v]) > 0.99 * self.bound_mm).any()]
        if at_bound:
            out["pose_warning"] = (f"the refined pose of view(s) {at_bound} stands at its bound "
                                   f"({math.degrees(self.bound_rad):g} deg, {self.bound_mm:g} mm): the rig is off by "
                                   "more than a refinement corrects; check the rig")
        return out

    def state_dict(self) -> dict:
        return {"omega": self.omega.clone(), "t": self.t.clone(), "fits": self.fits, "free": self.free.clone()}

    def load_state_dict(self, st: dict) -> None:
        if "omega" in st:
            self.omega, self.t, self.fits = st["omega"].to(self.omega), st["t"].to(self.t), int(st["fits"])
            self.free = st.get("free", self.omega.abs().sum(-1) > 0).cpu().clone()
            self.moved = bool(self.omega.any() or self.t.any())


def log_refined(found: dict) -> None:
    """The refined poses (``found``: :meth:`RefinedPoses.report`) in the log, the warning of one at its bound too;
    nothing where the poses are the rig's (``found`` empty)."""
    if not found:
        return
    log.info("refined poses: turns about the vertical axis %s deg (of zero mean: a turn every view shares, the rig "
             "turned as a whole, changes no image and turns the reconstruction with it; no refinement sees it); "
             "largest rotation %.2f deg, translation %.2f mm",
             ", ".join(f"{a:+.2f}" for a in found["pose_angle_deg"]), found["pose_rotation_max_deg"],
             found["pose_translation_max_mm"])
    if "pose_warning" in found:
        log.warning(found["pose_warning"])
