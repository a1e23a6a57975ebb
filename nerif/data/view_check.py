"""Each view of a capture checked on its own, before it enters the visual hull or the loss. One bad view (a
distorted image that is black, or a copy of its reference, a camera knocked between the exposures, a pair of
images swapped) otherwise erases the flame: the hull intersects every view's mask, and the loss fits what the
view says. A view found bad is left out with one warning naming it and why; too few left and the run stops.

Each check compares a view with itself (its two exposures, from :func:`nerif.sensing.measurement.images_compared`)
or with the other views (its displacements' size and sign), so that it holds for any flame."""
from __future__ import annotations

import logging

import numpy as np

from nerif.data.scene import Scene, hot_evidence

log = logging.getLogger(__name__)

SAME_IMAGE = 0.5 / 255  # RMS difference of the two exposures [full scale] below which they are one image
TEXTURE_LOST = 0.3  # the distorted exposure's contrast over its reference's below which its background is lost
ABSENT, WILD = 0.25, 4.0  # a view's RMS displacement against the views' median: below, no flame; above, no flow
SIGN = 0.2  # hot evidence (:func:`nerif.data.scene.hot_evidence`) beyond which a view's sign is clear
KNOCKED_PX = 1.0  # a shake larger than this [px of the full sensor] and than its flame's displacements: knocked


def _rms_displacement(scene: Scene, v: int) -> float:
    """A view's RMS image displacement [px of the full sensor] over its rays (0 where it has none)."""
    u = scene.displacement_px[scene.view_slice(v)].double()
    return float(u.norm(dim=-1).pow(2).mean().sqrt()) if len(u) else 0.0


def bad_views(scene: Scene) -> dict[int, str]:
    """The views of ``scene`` (a capture's, every view, before the held-out split) that are not to be used, each with
    the reason, in words: a distorted image equal to its reference or without the background's texture; a view
    whose displacements are nearly absent or wild against the other views' (below :data:`ABSENT` or above
    :data:`WILD` times their median RMS), point the other way from theirs where most agree on a hot flame, or are
    outweighed by a rigid shift between the exposures (the camera knocked)."""
    found = scene.measured or {}
    per_view = [{k: vals[v] for k, vals in found.items()} for v in range(scene.n_views)]
    why: dict[int, str] = {}
    counts = scene.view_counts().tolist()
    for v, f in enumerate(per_view):
        if counts[v] == 0:
            left = ", ".join(f"{100 * f[k]:.0f} % {k}" for k in ("saturated", "occluded", "unmeasured", "rejected")
                             if f.get(k, 0) > 0)
            why[v] = f"its measurement left no usable pixel where it sees the probe box ({left or 'nothing measured'})"
        elif f.get("difference_rms", 1.0) < SAME_IMAGE:
            why[v] = ("its distorted image equals its reference (the same file, or both taken without the flame?): "
                      "it holds no displacement")
        elif f.get("texture_ratio", 1.0) < TEXTURE_LOST:
            why[v] = (f"its distorted image has lost the background's texture ({100 * f['texture_ratio']:.0f} % of its "
                      "reference's contrast: black, flat, overexposed or out of focus?)")
    reach = {}  # each view's largest flame displacement (99th percentile) [px of the full sensor]
    for v in range(scene.n_views):
        u = scene.displacement_px[scene.view_slice(v)].double().norm(dim=-1)
        reach[v] = float(u.quantile(0.99)) if len(u) else 0.0
    rest = [v for v in range(scene.n_views) if v not in why]
    for v in rest:
        shake = float(np.hypot(*per_view[v].get("shake_px", (0.0, 0.0))))
        typical = float(np.median([reach[k] for k in rest if k != v])) if len(rest) > 1 else reach[v]
        if shake > KNOCKED_PX and shake > 3.0 * typical:
            why[v] = (f"the camera moved by {shake:.2f} px between its exposures, more than the flame's displacements "
                      f"({typical:.2f} px at most in the other views): knocked?")
    rms = {v: _rms_displacement(scene, v) for v in range(scene.n_views)}
    rest = [v for v in rms if v not in why]
    if len(rest) >= 3:
        for v in rest:
            typical = float(np.median([rms[k] for k in rest if k != v]))
            if rms[v] < ABSENT * typical:
                why[v] = (f"it shows almost no deflection ({rms[v]:.3f} px RMS against {typical:.3f} px, the other "
                          "views' median): a distorted image taken without the flame, or the reference again?")
            elif rms[v] > WILD * typical:
                why[v] = (f"its displacements are wild ({rms[v]:.3f} px RMS against {typical:.3f} px, the other "
                          "views' median): its flow failed (look at its images: a camera knocked, an image of another view?)")
    rest = [v for v in rest if v not in why]
    evidence = hot_evidence(scene, per_view=True)
    if len(rest) >= 3 and sum(evidence[v] < -SIGN for v in rest) >= 2 * len(rest) / 3:
        for v in rest:
            if evidence[v] > SIGN:
                why[v] = (f"its deflections point the way the other views' do not (hot evidence {evidence[v]:+.2f}, "
                          "the others below -0.2): its reference and distorted images swapped?")
    return why


def screened(scene: Scene, heldout: list[int], min_views: int = 3) -> Scene:
    """``scene`` (every view of a capture) without its :func:`bad_views`, each named in a warning, split into the
    training views and the ``heldout`` ones that remain; raises where fewer than ``min_views`` training views (or
    half of them) remain."""
    bad = bad_views(scene)
    for v, reason in sorted(bad.items()):
        log.warning("%s is left out: %s", scene.cameras[v].name, reason)
    if not bad:
        return scene.split_views(heldout)
    train = [v for v in range(scene.n_views) if v not in bad and v not in heldout]
    planned = scene.n_views - len([v for v in heldout if 0 <= v < scene.n_views])
    if len(train) < max(min_views, (planned + 1) // 2):
        raise ValueError(f"only {len(train)} of the {planned} training views are usable ("
                         + "; ".join(f"{scene.cameras[v].name}: {r}" for v, r in sorted(bad.items()))
                         + "): fix their images, or drop them from rig.yaml")
    keep = [v for v in range(scene.n_views) if v not in bad]
    held = [keep.index(v) for v in heldout if v in keep]
    if heldout and not held:
        log.warning("no held-out view remains: the run is scored on no view it did not train on")
    return scene.select_views(keep).split_views(held)
