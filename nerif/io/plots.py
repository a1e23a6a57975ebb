"""Figures people look at: temperature slices (truth, reconstruction, error) and curves."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from nerif.export import atomic_write  # noqa: E402
from nerif.geometry import ProbeBox  # noqa: E402


def extent(box: ProbeBox, vertical: int) -> list[float]:
    """imshow extent [mm] of a slice with x across and axis ``vertical`` (1: y, 2: z) up, to the voxel edges."""
    axes, h = box.axes(), box.voxel_mm / 2
    return [axes[0][0] - h, axes[0][-1] + h, axes[vertical][0] - h, axes[vertical][-1] + h]


# the heights of the horizontal slices and of the profiles across the axis: fractions of the probe box's height
# from its bottom, the same for every run on the same box
HEIGHTS = (0.25, 0.5, 0.75)
ERROR = "error (rec. - truth)"  # red: too hot, blue: too cold


def fixed_margins(fig, left: float, right: float, bottom: float, top: float, wspace: float = 0.25) -> None:
    """Place ``fig``'s subplots with margins in inches: a constrained layout measures every tick label on each draw,
    0.3-0.5 s of a figure's 0.6-1.1 s (``benchmarks/figures.py``)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h, wspace=wspace)


def height_indices(box: ProbeBox) -> list[int]:
    """The y indices of :data:`HEIGHTS` on ``box``: the voxel layer nearest each."""
    ny = box.shape[1]
    return [min(int(f * ny), ny - 1) for f in HEIGHTS]


def slice_figure(T: np.ndarray, box: ProbeBox, T_true: Optional[np.ndarray] = None, title: str = "",
                 unit: str = "K", std: Optional[np.ndarray] = None):
    """The central vertical slice (x-y at z = 0, the burner axis in it) and horizontal slices (x-z) at the heights
    :data:`HEIGHTS` of the box (dashed on the vertical slice), of the reconstruction ``T`` (nx, ny, nz), with the
    truth and the error (reconstruction less truth) where known, and its standard deviation where estimated (``std``,
    same unit). ``unit``: of the volumes (K, or sigma). Returns a figure."""
    ref = T_true if T_true is not None else T
    iz = box.shape[2] // 2
    _, ax_y, ax_z = box.axes()
    ext_xy, ext_xz = extent(box, 1), extent(box, 2)
    cols = [("reconstruction", T)] + ([("truth", T_true), (ERROR, T - T_true)] if T_true is not None else [])
    cols += [("uncertainty (1 std)", std)] if std is not None else []
    vmin, vmax = float(min(T.min(), ref.min())), float(max(T.max(), ref.max()))
    rows = [("x-y", None)] + [("x-z", iy) for iy in height_indices(box)]
    # one colour bar a column (its panels share the scale); fixed spacing: a tight layout of 4 x 4 panels costs a
    # second a figure, in every run and every TensorBoard image
    fig, axes = plt.subplots(len(rows), len(cols), figsize=(3.3 * len(cols) + 0.6, 3.1 * len(rows) + 0.5),
                             squeeze=False, height_ratios=[box.extent_mm[1] / box.extent_mm[2]] + [1] * (len(rows) - 1))
    fig.subplots_adjust(left=0.08, right=0.88, bottom=0.04, top=0.93, wspace=0.75, hspace=0.35)
    for j, (name, vol) in enumerate(cols):
        lim = float(np.abs(vol).max()) or 1.0
        kw = {ERROR: dict(cmap="RdBu_r", vmin=-lim, vmax=lim), "uncertainty (1 std)": dict(cmap="viridis", vmin=0,
              vmax=lim)}.get(name, dict(cmap="inferno", vmin=vmin, vmax=vmax))
        for i, (plane, iy) in enumerate(rows):
            ax = axes[i, j]
            img, ext = (vol[:, :, iz].T, ext_xy) if iy is None else (vol[:, iy, :].T, ext_xz)
            im = ax.imshow(img, origin="lower", extent=ext, **kw)
            ax.set_xlabel("x [mm]", fontsize=8, labelpad=1)
            ax.set_ylabel("y [mm] (burner axis)" if iy is None else "z [mm]", fontsize=8, labelpad=1)
            ax.tick_params(labelsize=7)
            ax.locator_params(nbins=4)  # 16 panels: every tick is an object drawn (a quarter of the figure's time)
            where = f"z = {ax_z[iz]:.1f} mm" if iy is None else f"y = {ax_y[iy]:.1f} mm"
            ax.set_title(f"{name} [{unit}], {where}", fontsize=8)
            if iy is None:
                for k in height_indices(box):
                    ax.axhline(ax_y[k], color="w", lw=0.6, ls="--")
        top, bottom = axes[0, j].get_position(), axes[-1, j].get_position()
        cax = fig.add_axes((top.x1 + 0.01, bottom.y0, 0.012, top.y1 - bottom.y0))
        bar = fig.colorbar(im, cax=cax)
        bar.set_label(f"{name} [{unit}]", fontsize=8)
        bar.ax.tick_params(labelsize=7)
    if title:
        fig.suptitle(title + " (dashed: the heights of the horizontal slices)", fontsize=10)
    return fig


def profiles_figure(T: np.ndarray, box: ProbeBox, T_true: Optional[np.ndarray] = None, title: str = "",
                    unit: str = "K", std: Optional[np.ndarray] = None):
    """Temperature along the burner axis (the voxel column nearest x = z = 0, against y), up the column of the hottest
    voxel where that is off the axis, and across the axis (along x, at the z of that column) at the heights
    :data:`HEIGHTS`, of the reconstruction ``T`` (nx, ny, nz) [``unit``] (with one standard deviation shaded where
    ``std`` is given) and of the truth where known (dashed). Lengths in mm. Returns a figure."""
    ax_x, ax_y, ax_z = box.axes()
    ix, iz = box.shape[0] // 2, box.shape[2] // 2  # the voxel column nearest the axis
    ref = T_true if T_true is not None else T
    px, _, pz = np.unravel_index(np.argmax(ref), ref.shape)  # the column of the hottest voxel (the truth's if known)
    heights = height_indices(box)
    columns = [((ix, iz), f"along the burner axis (x = {ax_x[ix]:.1f}, z = {ax_z[iz]:.1f} mm)")]
    if (px, pz) != (ix, iz):
        columns.append(((px, pz), f"vertical through the {'true ' if T_true is not None else ''}peak "
                                  f"(x = {ax_x[px]:.1f}, z = {ax_z[pz]:.1f} mm)"))
    fig, axes = plt.subplots(1, len(columns) + len(heights), figsize=(4.2 * (len(columns) + len(heights)), 4.2),
                             squeeze=False)
    fixed_margins(fig, left=0.65, right=0.15, bottom=0.5, top=0.65 if title else 0.35, wspace=0.28)
    lines = [(ax_y, T[i, :, k], None if std is None else std[i, :, k], None if T_true is None else T_true[i, :, k],
              name, "y [mm]") for (i, k), name in columns]
    lines += [(ax_x, T[:, iy, iz], None if std is None else std[:, iy, iz],
               None if T_true is None else T_true[:, iy, iz], f"across, y = {ax_y[iy]:.1f} mm (z = {ax_z[iz]:.1f} mm)",
               "x [mm]")
              for iy in heights]
    lo = min(float(np.min(T)), float(np.min(T_true)) if T_true is not None else np.inf)
    hi = max(float(np.max(T)), float(np.max(T_true)) if T_true is not None else -np.inf)
    pad = 0.05 * (hi - lo) or 1.0
    for ax, (pos, rec, sd, true, name, xlabel) in zip(axes[0], lines):
        ax.plot(pos, rec, color="C3", label="reconstruction")
        if sd is not None:
            ax.fill_between(pos, rec - sd, rec + sd, color="C3", alpha=0.25, label="+- 1 std")
        if true is not None:
            ax.plot(pos, true, color="k", ls="--", label="truth")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"T [{unit}]" if unit == "K" else f"[{unit}]")
        ax.set_ylim(lo - pad, hi + pad)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def sequence_figure(frames: list[tuple[str, np.ndarray, Optional[np.ndarray]]], box: ProbeBox, unit: str = "K",
                    title: str = ""):
    """The central vertical slice (x-y at z = 0) of every frame of a time series side by side, over the truth
    where known, on one colour scale. ``frames``: (label, volume, true volume or None) per frame."""
    truth = [t for _, _, t in frames if t is not None]
    rows = [("reconstruction", [v for _, v, _ in frames])] + ([("truth", truth)] if len(truth) == len(frames) else [])
    every = [v for _, vols in rows for v in vols]
    vmin, vmax = float(min(v.min() for v in every)), float(max(v.max() for v in every))
    ext, iz = extent(box, 1), box.shape[2] // 2
    fig, axes = plt.subplots(len(rows), len(frames), figsize=(1.9 * len(frames) + 1.2, 3.0 * len(rows) + 0.6),
                             squeeze=False)
    for i, (name, vols) in enumerate(rows):
        for j, vol in enumerate(vols):
            ax = axes[i, j]
            im = ax.imshow(vol[:, :, iz].T, origin="lower", extent=ext, cmap="inferno", vmin=vmin, vmax=vmax)
            ax.set_title(f"{frames[j][0]}" if i == 0 else "", fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
        axes[i, 0].set_ylabel(f"{name}\nx-y at z = 0", fontsize=8)
    fig.colorbar(im, ax=axes.ravel().tolist(), fraction=0.02, label=unit)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def save_figure(fig, path: Path) -> Path:
    path = atomic_write(Path(path), lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
    return path


def png_bytes(fig) -> bytes:
    """``fig`` as PNG bytes, as :func:`save_figure` writes it (closed after)."""
    import io

    buffer = io.BytesIO()
    fig.savefig(buffer, dpi=110, format="png")
    plt.close(fig)
    return buffer.getvalue()


TERM_NAMES = {"loss": "total", "loss_boundary": "ambient faces (sigma = 0)", "loss_tv": "total variation"}


# the evaluation figure curves.png follows, with its axis label
EVALUATED = {"temperature_rmse_K": "T RMSE over the probe box [K]",
             "deflection_rmse": "deflection RMSE on training rays [{unit}]"}


def curves_figure(history: list[dict], losses: list[tuple[int, dict]], images_from: Optional[int] = None,
                  deflection_unit: str = "rad"):
    """Each term of the training loss against iteration (``losses``: (iteration, the step's terms), as the solver
    names them), the switch from the flow's deflections to the images marked at ``images_from``; and the
    evaluation errors against wall time (the temperature's RMSE where a truth is known, else the deflections', in
    ``deflection_unit``). The data term is normalised by what it compares (the deflections' or the images' mean
    square), so its level changes where the fit switches from one to the other."""
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4.4))
    fixed_margins(fig, left=1.1, right=0.15, bottom=1.2, top=0.35, wspace=0.3)  # below: the legend's rows
    if losses:
        it = np.array([i for i, _ in losses])
        names = [k for k in losses[0][1] if k.startswith("loss")]
        for k in names:
            v = np.array([t.get(k, np.nan) for _, t in losses], dtype=float)
            label = TERM_NAMES.get(k, f"data term ({k[5:]} gradients)")
            if k == "loss":  # on top, dashed: where the sum is the data term alone the two lines lie on each other
                a.semilogy(it, v, color="k", lw=1.2, ls="--", zorder=3, label=label + " (sum of the terms)")
            elif k in TERM_NAMES or images_from is None:
                a.semilogy(it, v, lw=1.6, label=label + ("" if k in TERM_NAMES else ": flow deflections"))
            else:  # the data term: the flow's deflections, then the images with the flow term beside them
                flow, images = it < images_from, it >= images_from
                a.semilogy(it[flow], v[flow], lw=1.6, label=f"{label}: flow deflections")
                a.semilogy(it[images], v[images], lw=1.6, label=f"{label}: images + flow")
        if images_from is not None and it[0] <= images_from <= it[-1]:
            a.axvline(images_from, color="0.4", ls="--", lw=0.8)
            a.annotate("flow -> images", (images_from, 0), xycoords=("data", "axes fraction"), xytext=(3, 4),
                       textcoords="offset points", fontsize=7, color="0.3")
        a.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False)
    a.set_xlabel("iteration")
    a.set_ylabel("training loss terms (normalised, 1)")
    a.set_title("training loss", fontsize=9)
    key = "temperature_rmse_K" if history and history[0].get("temperature_rmse_K") is not None else "deflection_rmse"
    if history:
        t, y = [h["wall_time_s"] for h in history], [h[key] for h in history]
        b.plot(t, y, "o-", ms=4)
        if len(history) < 3:  # too few evaluations for a curve: say what they were
            for ti, yi, h in zip(t, y, history):
                b.annotate(f"{yi:.3g} at iteration {h.get('iteration', '?')}", (ti, yi), xytext=(4, 4),
                           textcoords="offset points", fontsize=7)
            b.text(0.02, 0.02, "few evaluations: train.eval_every sets how often", transform=b.transAxes,
                   fontsize=7, color="0.3")
    b.set_xlabel("training wall time [s]")
    b.set_ylabel(EVALUATED[key].format(unit=deflection_unit))
    b.set_title("error during training (fixed evaluation rays)", fontsize=9)
    return fig


def image_panels(panels: list, title: str, width_in: float = 3.2, height_in: float = 4.2):
    """A row of images without axes, each with its title and colour bar: ``panels`` = (title, image, imshow
    keywords). Returns the figure."""
    # fixed spacing (no axes ticks to measure): a constrained layout doubles the second each view's figure costs
    fig, axes = plt.subplots(1, len(panels), figsize=(width_in * len(panels), height_in), squeeze=False)
    fig.subplots_adjust(left=0.01, right=0.97, bottom=0.03, top=0.86, wspace=0.25)
    for ax, (name, img, kw) in zip(axes[0], panels):
        im = ax.imshow(img, **kw)
        ax.set_title(name, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03)
    fig.suptitle(title, fontsize=10)
    return fig


HOLES = "grey: no ray (left out by the measurement, outside the region or the view's box, or masked)"


def heldout_figure(observed: np.ndarray, predicted: np.ndarray, unit: str, title: str = "", block_px: int = 1):
    """One held-out view: observed and predicted magnitude, and the magnitude of their difference, on the view's
    pixels (axes in pixels of the full sensor), grey where the view has no ray (:data:`HOLES`).

    Args:
        observed, predicted: (h, w, C) vectors on the camera's ray grid, NaN where there is no ray.
        unit: of the vectors (px for displacements, rad or sigma for deflections).
        block_px: sensor pixels across a ray (the ray grid's binning).
    """
    mag_o, mag_p = np.linalg.norm(observed, axis=-1), np.linalg.norm(predicted, axis=-1)
    diff = np.linalg.norm(predicted - observed, axis=-1)
    vmax = float(np.nanmax(mag_o)) if np.isfinite(mag_o).any() else 1.0
    dmax = float(np.nanmax(diff)) if np.isfinite(diff).any() else 1.0
    h, w = mag_o.shape
    what = "displacement" if unit == "px" else "deflection"
    panels = [(f"observed |{what}| [{unit}]", mag_o, dict(cmap="viridis", vmin=0, vmax=vmax or 1.0)),
              (f"predicted |{what}| [{unit}]", mag_p, dict(cmap="viridis", vmin=0, vmax=vmax or 1.0)),
              (f"|predicted - observed| [{unit}]", diff, dict(cmap="magma", vmin=0, vmax=dmax or 1.0))]
    fig, axes = plt.subplots(1, 3, figsize=(11.5, 3.2 * h / max(w, 1) + 1.6), squeeze=False)
    fixed_margins(fig, left=0.7, right=0.95, bottom=0.5, top=0.75, wspace=0.6)  # a colour bar right of each
    for ax, (name, img, kw) in zip(axes[0], panels):
        im = ax.imshow(img, extent=(0, w * block_px, h * block_px, 0), interpolation="nearest", **kw)
        ax.set_facecolor("#b0b0b0")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("column [px]")
        ax.set_ylabel("row [px]")
        fig.colorbar(im, ax=ax, fraction=0.046, label=f"[{unit}]")
    fig.suptitle(f"{title}\n{HOLES}" if title else HOLES, fontsize=9)
    return fig


def masks_figure(values: list, masks: list, names: list, unit: str, block_px: int = 1):
    """Every view's 2-D mask over what it was made from: per view (``values``: (h, w) the magnitude of each ray's
    measured deflection [``unit``], NaN where the view has no ray; ``masks``: (h, w) bool, the rays trained on),
    the magnitude with the mask's edge drawn in white; axes in pixels of the full sensor (``block_px`` across a
    ray). Returns a figure."""
    n = len(values)
    cols = min(n, 6)
    rows = -(-n // cols)
    h, w = values[0].shape
    fig, axes = plt.subplots(rows, cols, figsize=(2.6 * cols, 2.6 * rows * h / max(w, 1) + 0.9), squeeze=False,
                             sharex=True, sharey=True)  # one grid for all: the tick labels on the edges only
    vmax = max((float(np.nanpercentile(v, 99.5)) for v in values if np.isfinite(v).any()), default=1.0) or 1.0
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    for ax, val, mask, name in zip(axes.ravel(), values, masks, names):
        ext = (0, val.shape[1] * block_px, val.shape[0] * block_px, 0)
        im = ax.imshow(val, extent=ext, cmap="viridis", vmin=0, vmax=vmax, interpolation="nearest")
        ax.set_facecolor("#b0b0b0")
        if mask.any() and not mask.all():
            ax.contour(mask.astype(float), levels=[0.5], colors="w", linewidths=0.8, origin="upper", extent=ext)
        ax.set_title(f"{name}: {100 * float(np.mean(mask)):.0f} % inside", fontsize=7)
        ax.tick_params(labelsize=6)
    for ax in axes[:, 0]:
        ax.set_ylabel("row [px]", fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("column [px]", fontsize=7)
    fig.colorbar(im, ax=axes.ravel().tolist(), fraction=0.02, label=f"|measured deflection| [{unit}]")
    fig.suptitle("2-D masks: training rays are drawn inside the white lines (grey: no ray)", fontsize=9)
    return fig


def sensing_figure(reference: np.ndarray, distorted: np.ndarray, ut: np.ndarray, ue: np.ndarray, crop_px: int = 160,
                   title: str = ""):
    """One view of realistic sensing: its 8-bit ``reference`` and ``distorted`` images (H, W) cropped around the
    largest displacement, the true (``ut``) and estimated (``ue``) displacement magnitude, (h, w, 2) each [image px]
    on the training grid, and their difference."""
    h, w = ut.shape[:2]
    H, W = reference.shape
    r, c = np.unravel_index(np.argmax(np.linalg.norm(ut, axis=-1)), (h, w))
    rr = int(np.clip((r + 0.5) * H / h - crop_px // 2, 0, max(H - crop_px, 0)))
    cc = int(np.clip((c + 0.5) * W / w - crop_px // 2, 0, max(W - crop_px, 0)))
    crop = (slice(rr, rr + crop_px), slice(cc, cc + crop_px))
    mag_t, mag_e = np.linalg.norm(ut, axis=-1), np.linalg.norm(ue, axis=-1)
    diff = np.linalg.norm(ue - ut, axis=-1)
    vmax = float(np.nanmax(mag_t)) or 1.0
    panels = [("reference (crop)", reference[crop], dict(cmap="gray", vmin=0, vmax=255)),
              ("distorted (crop)", distorted[crop], dict(cmap="gray", vmin=0, vmax=255)),
              ("|u| true [px]", mag_t, dict(cmap="viridis", vmin=0, vmax=vmax)),
              ("|u| estimated [px]", mag_e, dict(cmap="viridis", vmin=0, vmax=vmax)),
              ("|u est - u true| [px]", diff, dict(cmap="magma", vmin=0, vmax=float(np.nanmax(diff)) or 1.0))]
    return image_panels(panels, title or "realistic sensing")


# the colours of the causes a pixel was left out for (nerif.sensing.measurement.CAUSES after "kept")
CAUSE_COLOURS = ("#9e9e9e", "#ffd400", "#e0218a", "#00b7ff", "#ff5a00")


def measured_figure(reference: np.ndarray, displacement: np.ndarray, left_out: np.ndarray, causes: tuple,
                    title: str = "", unit: str = "px"):
    """One view's measurement: the reference image (H, W) with the ray-grid pixels left out coloured by cause
    (``left_out``: (h, w) indices into ``causes``, 0 kept; the legend gives each cause's share of the ray grid), and
    beside it the displacement magnitude (``displacement``: (h, w, 2) [``unit``], NaN where left out) on the same
    pixel axes, with a colour bar. Returns a figure."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    H, W = reference.shape
    h, w = left_out.shape
    extent = (-0.5, W - 0.5, H - 0.5, -0.5)  # image pixels, row 0 at the top
    height = 4.4 * H / max(W, 1) + 1.0
    fig, axes = plt.subplots(1, 2, figsize=(11.0, height), squeeze=False)
    fixed_margins(fig, left=0.66, right=0.77, bottom=0.5, top=0.62, wspace=0.22)  # labels below, two title lines above
    ax = axes[0, 0]
    ax.imshow(reference, cmap="gray", extent=extent, vmin=0, vmax=float(np.max(reference)) or 1.0)
    overlay = np.ma.masked_equal(left_out, 0)
    colours = ListedColormap(("#000000",) + CAUSE_COLOURS[:len(causes) - 1])
    ax.imshow(overlay, cmap=colours, vmin=-0.5, vmax=len(causes) - 0.5, alpha=0.6, extent=extent,
              interpolation="nearest")
    shares = [(np.mean(left_out == k), name, CAUSE_COLOURS[k - 1]) for k, name in enumerate(causes) if k]
    handles = [Patch(color=c, alpha=0.6, label=f"{name} {100 * s:.1f} %") for s, name, c in shares if s > 0]
    kept = float(np.mean(left_out == 0))
    ax.legend(handles=handles or [Patch(color="none", label="nothing left out")], loc="lower right", fontsize=7,
              title=f"kept {100 * kept:.1f} % of the rays", title_fontsize=7, framealpha=0.8)
    ax.set_title("reference, what was left out and why", fontsize=9)
    ax = axes[0, 1]
    magnitude = np.linalg.norm(displacement, axis=-1)
    finite = magnitude[np.isfinite(magnitude)]
    im = ax.imshow(magnitude, cmap="viridis", extent=extent, vmin=0,
                   vmax=float(np.percentile(finite, 99.5)) if finite.size else 1.0, interpolation="nearest")
    ax.set_facecolor("#d0d0d0")  # left out: no displacement
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03, label=f"|displacement| [{unit}]")
    ax.set_title(f"displacement magnitude ({h} x {w} rays; grey: left out)", fontsize=9)
    for ax in axes[0]:
        ax.set_xlabel("column [px]")
        ax.set_ylabel("row [px]")
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


ROTATION_NOTE = ("nerif's convention: a view's angle turns from +z towards +x, counter-clockwise seen from above "
                 "(y up);\nimage columns run to the right, rows down")


def _box_edges(box: ProbeBox) -> np.ndarray:
    """(12, 2, 3) the probe box's edges [mm], the box centred on the origin."""
    h = np.asarray(box.half_mm, dtype=np.float64)
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
    pairs = [(a, b) for a in range(8) for b in range(a + 1, 8) if np.sum(corners[a] != corners[b]) == 1]
    return np.stack([corners[[a, b]] for a, b in pairs])


def _rig_from_above(top, cameras: list, box: ProbeBox, heldout: set) -> None:
    """:func:`rig_figure`'s left panel on axes ``top``: the cameras, their names, angles and lines of sight, the
    box's footprint and the arrow of the order's sense of rotation."""
    pos = np.stack([np.asarray(c.position, dtype=np.float64) for c in cameras])
    h = np.asarray(box.half_mm, dtype=np.float64)
    top.add_patch(plt.Rectangle((-h[0], -h[2]), 2 * h[0], 2 * h[2], fill=False, color="k", lw=1.2))
    for v, (c, p) in enumerate(zip(cameras, pos)):
        held = v in heldout
        colour = "tab:orange" if held else "tab:blue"
        top.plot([p[0], 0], [p[2], 0], color=colour, lw=0.5, alpha=0.5)
        top.plot(p[0], p[2], "o", color=colour)
        angle = "" if "deg" in c.name else f"\n{np.degrees(np.arctan2(p[0], p[2])):.1f} deg"
        top.annotate(f"{c.name}{angle}" + ("\nheld out" if held else ""), (p[0], p[2]), fontsize=7,
                     textcoords="offset points", xytext=(6, 4), color=colour)
    if len(cameras) > 1:
        a, b = 0.55 * pos[0], 0.55 * pos[1]
        turn = np.sign(pos[0][2] * pos[1][0] - pos[0][0] * pos[1][2])  # from z towards x: + counter-clockwise from above
        top.annotate("", xy=(b[0], b[2]), xytext=(a[0], a[2]),
                     arrowprops={"arrowstyle": "->", "connectionstyle": f"arc3,rad={0.3 * turn}", "color": "k"})
        sense = "counter-clockwise" if turn > 0 else "clockwise"
        top.set_title(f"seen from above: the views in their order turn {sense}", fontsize=9)
    top.set_xlabel("x [mm]")
    top.set_ylabel("z [mm] (down the page: seen from above)")
    top.set_aspect("equal")
    top.invert_yaxis()


def rig_figure(cameras: list, box: ProbeBox, heldout: set, pictures: list, title: str = ""):
    """The rig seen from above beside each view's picture with the box drawn where the rig puts it.

    Args:
        cameras: every view's :class:`~nerif.geometry.Camera`, in the rig's order (positions [mm]).
        box: the probe box, centred on the origin.
        heldout: indices of the views held out of training.
        pictures: per view None, or (image (h, w) on the camera's pixel grid, its label): the measured displacement
            magnitude (the flame as the view sees it) or the reference.
        title: the figure's title.

    Left: the cameras (x right, z down: seen from above, y towards the reader) with their names and angles, their
    lines of sight, the box's footprint and an arrow from the first view to the second (the order's sense of
    rotation). Right: each picture with the box's edges and the world's +x (red) and +y (green) from the box centre
    projected into it, so that an object placed on the burner's +x side can be checked in the images."""
    shown = [v for v, p in enumerate(pictures) if p is not None]
    cols = min(4, max(len(shown), 1))
    rows = max(1, -(-len(shown) // cols))
    if shown:
        fig = plt.figure(figsize=(5.5 + 2.4 * cols, max(5.5, 2.9 * rows)))
        # the view from above, then the pictures: the gap between them leaves room for the cameras' names
        outer = fig.add_gridspec(1, 2, width_ratios=(2, cols), wspace=0.2)
        top = fig.add_subplot(outer[0])
        grid = outer[1].subgridspec(rows, cols, hspace=0.3, wspace=0.15)
    else:  # no pictures (deflections given): the view from above alone
        fig, top = plt.subplots(figsize=(7.5, 7.5))
    fixed_margins(fig, left=0.9, right=0.2, bottom=0.55, top=0.95, wspace=0.15)  # above: three lines of title
    _rig_from_above(top, cameras, box, heldout)
    h = np.asarray(box.half_mm, dtype=np.float64)
    edges = _box_edges(box)
    for k, v in enumerate(shown):
        ax = fig.add_subplot(grid[k // cols, k % cols])
        image, label = pictures[v]
        ax.imshow(image, cmap="gray" if label == "reference" else "magma")
        cam = cameras[v]
        for e in cam.project(edges) - 0.5:  # pixel centres at +0.5, imshow's at 0
            ax.plot(e[:, 0], e[:, 1], color="tab:cyan", lw=0.8)
        for axis, colour in ((0, "red"), (1, "lime")):
            tip = np.zeros((2, 3))
            tip[1, axis] = h[axis]
            (x0, y0), (x1, y1) = cam.project(tip) - 0.5
            ax.annotate("", xy=(x1, y1), xytext=(x0, y0), arrowprops={"arrowstyle": "->", "color": colour})
        ax.set_title(cam.name.split(" (")[0] + (", held out" if v in heldout else ""), fontsize=8)
        ax.set_xlim(-0.5, cam.width - 0.5)
        ax.set_ylim(cam.height - 0.5, -0.5)
        ax.set_xticks([])
        ax.set_yticks([])
    labels = sorted({p[1] for p in pictures if p is not None})
    fig.suptitle((title or "the rig") + (f"; in each view ({', '.join(labels)}) the probe box (cyan) and the world's "
                                         "+x (red) and +y (green) from its centre" if labels else "")
                 + f"\n{ROTATION_NOTE}", fontsize=9)
    return fig
