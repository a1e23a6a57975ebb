"""The checks of a scene's data, each threshold and sentence here: each view of a capture checked on its own
(:func:`screened`), what concerns the whole capture (:func:`beyond_the_box`, :func:`clipping`), the deflections'
sign (:func:`check_sign`), whether the views can fix a 3-D field at all (:func:`ill_posed`) and the directions they
leave unseen (:func:`missing_wedge`).

Each view of a capture is checked on its own, before it enters the visual hull or the loss. One bad view (a
distorted image that is black, or a copy of its reference, a camera knocked between the exposures, a pair of
images swapped) otherwise erases the flame: the hull intersects every view's mask, and the loss fits what the
view says. A view found bad is left out with one warning naming it and why; too few left and the run stops.

Each check compares a view with itself (its two exposures, from :func:`nerif.sensing.measurement.images_compared`)
or with the other views (its displacements' size and sign), so that it holds for any flame. Two more say what
concerns the whole capture without leaving a view out: the flame seen beyond the probe box (:func:`beyond_the_box`)
and exposures clipped at full scale (:func:`clipping`)."""
from __future__ import annotations

import logging

import numpy as np

from nerif.data.scene import Scene
from nerif.geometry import Camera, rig_axis
from nerif.sensing.findings import Findings

log = logging.getLogger(__name__)

SAME_IMAGE = 0.5 / 255  # RMS difference of the two exposures [full scale] below which they are one image
TEXTURE_LOST = 0.3  # the distorted exposure's contrast over its reference's below which its background is lost
ABSENT, WILD = 0.25, 4.0  # a view's RMS displacement against the views' median: below, no flame; above, no flow
SIGN = 0.2  # hot evidence (:func:`hot_evidence`) beyond which the deflections' sign is clear (a flame: -0.3 to -1)
MIN_DIRECTIONS = 3  # distinct viewing directions a 3-D field needs
SPAN_DEG = 30.0  # the widest angle between viewing axes below which tomography is ill-posed [deg]
FILLED = 0.05  # a view with fewer of its rays (in the region of interest) missing the probe box than this: the box fills
               # its frame (the shared captures: 0.54-0.66; their pitch halved, as for images binned 2 x 2 in the
               # camera: 0.00)
WEDGE_DEG = 45.0  # the widest gap of viewing directions [deg] beyond which a run says what it leaves unmeasured: with
                 # exact deflections, 9 views over 120 deg (a 60 deg gap) read two flames' peaks 7 and 14 % cold, 9
                 # over 160 deg (20 deg) 5 and 3 %, 18 over 170 deg 2.5 % (benchmarks/RESULTS.md, issue 66); 9 over
                 # 160 deg less a held-out view at an end leave 40 deg
UNBOUNDED_DEG = 90.0  # a widest gap beyond this [deg] leaves more directions unseen than seen: a core's peak is
                     # bounded above by the prior alone (7 views over 90 deg less one held out at its end, a 105 deg
                     # gap: a 1986 K core read 1086 K, its field 916 K; benchmarks/RESULTS.md, issue 66)
GAP_TIE_DEG = 1.0  # widest gaps within this [deg] of each other are one (the held-out view: the last of them)
RADIANS_DEG = 6.5  # a span below this [deg] is what angles of a wide arc given in radians look like (0 to 2.6 rad)
KNOCKED_PX = 1.0  # a shake larger than this [px of the full sensor] and than its flame's displacements: knocked
CLIPPED = 0.10  # a view with more of its pixels at full scale than this is said to clip: nerif's own chain clips the
                # dots' centres of 2 % (the default rig) to 7 % (40 um pixels, written captures) of a well-exposed
                # view's pixels; a 2x gain clipped at full scale 22 %
OUTSIDE = 0.5  # displacements outside the box's image above this share of those inside: the flame is not in the box


def _rms_displacement(scene: Scene, v: int) -> float:
    """A view's RMS image displacement [px of the full sensor] over its rays (0 where it has none)."""
    u = scene.displacement_px[scene.view_slice(v)].double()
    return float(u.norm(dim=-1).pow(2).mean().sqrt()) if len(u) else 0.0


def _reach(scene: Scene, v: int) -> float:
    """A view's largest flame displacement, the 99th percentile of their size over its rays [px of the full
    sensor] (0 where it has none)."""
    u = scene.displacement_px[scene.view_slice(v)].double().norm(dim=-1)
    return float(u.quantile(0.99)) if len(u) else 0.0


def beyond_the_box(scene: Scene) -> str:
    """A sentence where the views see displacements outside the probe box's image nearly as large as inside it
    (above :data:`OUTSIDE` of them; the measurement's ``outside_px``), else \"\". Outside the box's image no flame
    should deflect: there the flow reads its noise (a sixth of the flame's on the shared captures). Where it reads
    the flame, the flame is larger than the box, or the rig's geometry (focal length, pitch, distances, binning in
    the camera) draws the box smaller or elsewhere than it is in the images; a field in the box cannot explain
    those rays either way."""
    outside = [f.outside_px for f in scene.findings] if scene.findings else [None] * scene.n_views
    seen = [(v, o, _reach(scene, v)) for v, o in enumerate(outside) if o is not None]
    hit = [(v, o, r) for v, o, r in seen if r > 0 and o > OUTSIDE * r]
    if not hit:
        return ""
    names = ", ".join(scene.cameras[v].name for v, _, _ in hit)
    o, r = float(np.median([h[1] for h in hit])), float(np.median([h[2] for h in hit]))
    return (f"{len(hit)} of {len(seen)} views see the flame outside the probe box's image ({names}: {o:.2f} px "
            f"there against {r:.2f} px inside, 99th percentiles): the flame reaches beyond the probe box, or the rig's "
            "geometry (camera.focal_mm, pitch_um with the images' binning in the camera, the distances) draws the box "
            "elsewhere than it is; enlarge probe.shape or check rig.yaml")


def clipping(scene: Scene) -> str:
    """A sentence naming the views with more than :data:`CLIPPED` of their pixels at full scale in either exposure
    (the measurement's ``clipped``), else "". Those pixels are kept where the texture survives around them (the
    centres of bright dots), but the flow reads their displacement less well: with a 2x gain clipped at full scale,
    the error of a run rose 3.6-fold (issue 38's probe)."""
    clipped = [f.clipped for f in scene.findings] if scene.findings else [None] * scene.n_views
    hit = [(scene.cameras[v].name, c) for v, c in enumerate(clipped) if c is not None and c > CLIPPED]
    if not hit:
        return ""
    worst = max(c for _, c in hit)
    return (f"{', '.join(n for n, _ in hit)}: up to {100 * worst:.0f} % of the pixels are at full scale in an exposure "
            "(clipped), where the flow reads displacements less well: lower the exposure or the gain")


def bad_views(scene: Scene) -> dict[int, str]:
    """The views of ``scene`` (a capture's, every view, before the held-out split) that are not to be used, each with
    the reason, in words: a distorted image equal to its reference or without the background's texture; a view
    whose displacements are nearly absent or wild against the other views' (below :data:`ABSENT` or above
    :data:`WILD` times their median RMS), point the other way from theirs where most agree on a hot flame, or are
    outweighed by a rigid shift between the exposures (the camera knocked)."""
    per_view = scene.findings or [Findings() for _ in range(scene.n_views)]
    why: dict[int, str] = {}
    counts = scene.view_counts().tolist()
    for v, f in enumerate(per_view):
        if counts[v] == 0:
            left = ", ".join(f"{100 * share:.0f} % {k}" for k, share in (
                ("saturated", f.saturated), ("occluded", f.occluded), ("unmeasured", f.unmeasured),
                ("rejected", f.rejected)) if share)
            why[v] = f"its measurement left no usable pixel where it sees the probe box ({left or 'nothing measured'})"
        elif f.difference_rms is not None and f.difference_rms < SAME_IMAGE:
            why[v] = ("its distorted image equals its reference (the same file, or both taken without the flame?): "
                      "it holds no displacement")
        elif f.texture_ratio is not None and f.texture_ratio < TEXTURE_LOST:
            why[v] = (f"its distorted image has lost the background's texture ({100 * f.texture_ratio:.0f} % of its "
                      "reference's contrast: black, flat, overexposed or out of focus?)")
    reach = {v: _reach(scene, v) for v in range(scene.n_views)}
    rest = [v for v in range(scene.n_views) if v not in why]
    for v in rest:
        shake = float(np.hypot(*(per_view[v].shake_px or (0.0, 0.0))))
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
                          "views' median): its flow failed (look at its images: a camera knocked, an image of another "
                          "view?)")
    rest = [v for v in rest if v not in why]
    evidence = hot_evidence(scene, per_view=True)
    if len(rest) >= 3 and sum(evidence[v] < -SIGN for v in rest) >= 2 * len(rest) / 3:
        for v in rest:
            if evidence[v] > SIGN:
                why[v] = (f"its deflections point the way the other views' do not (hot evidence {evidence[v]:+.2f}, "
                          f"the others below -{SIGN:g}): its reference and distorted images swapped?")
    return why


def _grouped(scene: Scene, bad: dict[int, str]) -> list[tuple[str, str]]:
    """(the views' names, the reason) once a reason, naming every view it holds for."""
    by_reason: dict[str, list[str]] = {}
    for v, reason in sorted(bad.items()):
        by_reason.setdefault(reason, []).append(scene.cameras[v].name)
    return [(", ".join(names), reason) for reason, names in by_reason.items()]


def screened(scene: Scene, heldout: list[int], min_views: int = 3) -> Scene:
    """``scene`` (every view of a capture) without its :func:`bad_views`, each named in a warning (views left out
    for one reason in one), split into the training views and the ``heldout`` ones that remain; raises where fewer
    than ``min_views`` training views (or half of them) remain. Warns where the views kept see the flame beyond the
    probe box (:func:`beyond_the_box`)."""
    bad = bad_views(scene)
    train = [v for v in range(scene.n_views) if v not in bad and v not in heldout]
    planned = scene.n_views - len([v for v in heldout if 0 <= v < scene.n_views])
    if bad and len(train) < max(min_views, (planned + 1) // 2):
        groups = _grouped(scene, bad)
        if len(groups) == 1 and len(bad) == scene.n_views:  # one cause everywhere: the capture or a setting
            raise ValueError(f"no view is usable: in every view, {groups[0][1]}")
        raise ValueError(f"only {len(train)} of the {planned} training views are usable ("
                         + "; ".join(f"{names}: {reason}" for names, reason in groups)
                         + "): fix their images, or drop them from rig.yaml")
    for names, reason in _grouped(scene, bad):
        log.warning("%s %s left out: %s", names, "is" if "," not in names else "are", reason)
    keep = [v for v in range(scene.n_views) if v not in bad]
    kept = scene.select_views(keep) if bad else scene
    for said in (beyond_the_box(kept), clipping(kept)):
        if said:
            log.warning("%s", said)
    if not bad:
        return scene.split_views(heldout)
    held = [keep.index(v) for v in heldout if v in keep]
    if heldout and not held:
        log.warning("no held-out view remains: the run is scored on no view it did not train on")
    return kept.split_views(held)


def hot_evidence(scene: Scene, per_view: bool = False):
    """How clearly the observed deflections show gas hotter (less refractive) than ambient, within [-1, 1]:
    -1 for a hot flame seen by every view, +1 for the reverse (reference and distorted images swapped, or the
    deflections' sign reversed). Per view and image row, the deflection along the row, ``g = dP/dc`` with ``P``
    the line integral of sigma along the rays, has the first moment ``sum_c (c - c_mean) g_c = -sum_c P_c`` (up to
    the rows' ends): negative where ``P`` is, as through a flame. Returns the moments summed over rows and views,
    over the sum of their magnitudes (``per_view``: a list, each view's own). Measured: -0.75 to -1.0 on the
    synthetic flames, -0.81 on the independent capture through the optical flow, -0.35 on the paper's Phantom 1."""
    sums = []
    for v in range(scene.n_views):
        sl = scene.view_slice(v)
        e = scene.view_image(v, scene.observed[sl].double().cpu().numpy(), np.nan)
        d = scene.view_image(v, scene.dirs[sl].double().cpu().numpy(), np.nan)
        along = d[:, 1:] - d[:, :-1]  # the world direction in which the column grows
        along /= np.linalg.norm(along, axis=-1, keepdims=True)
        g = (0.5 * (e[:, 1:] + e[:, :-1]) * along).sum(-1)
        ok = np.isfinite(g)
        g = np.where(ok, g, 0.0)
        c = np.arange(g.shape[1], dtype=np.float64)[None, :]
        c_mean = (c * ok).sum(1, keepdims=True) / np.maximum(ok.sum(1, keepdims=True), 1)
        moment = (c - c_mean) * g
        sums.append((-moment.sum(), np.abs(moment).sum()))  # -sum_c P_c, and the scale
    if per_view:
        return [float(n / d) if d > 0 else 0.0 for n, d in sums]
    num, den = sum(n for n, _ in sums), sum(d for _, d in sums)
    return float(num / den) if den > 0 else 0.0


def view_directions(cameras: list[Camera], tol_deg: float = 1.0) -> int:
    """How many distinct directions the cameras look along (axes within ``tol_deg`` count as one, as do opposite
    ones: a ray and its reverse see the same line integral)."""
    axes = [np.asarray(c.rotation)[:, 2] for c in cameras]
    distinct: list[np.ndarray] = []
    for a in axes:
        if all(abs(float(a @ b)) < np.cos(np.deg2rad(tol_deg)) for b in distinct):
            distinct.append(a)
    return len(distinct)


def view_span_deg(cameras: list[Camera]) -> float:
    """The widest angle between two cameras' viewing axes [deg], opposite axes counting as one (0 to 90)."""
    axes = np.stack([np.asarray(c.rotation)[:, 2] for c in cameras])
    cos = np.clip(np.abs(axes @ axes.T), 0.0, 1.0)
    return float(np.rad2deg(np.arccos(cos.min())))


def box_fills_frame(cameras: list[Camera], quiet: list[np.ndarray], roi: np.ndarray, box, source: str) -> list[str]:
    """One sentence (logged, and returned) where the probe box fills some views' frames: fewer than :data:`FILLED`
    of their rays in the region of interest ``roi`` (h, w) miss the box (``quiet``, per view (h, w) bool:
    :func:`nerif.geometry.outside_the_box`). A real capture shows the undisturbed background around its flame (the
    measurement reads the shake and the noise there); a frame that the box fills is, far more often than a real
    set-up, a scale off by a factor: images binned in the camera with the unbinned pixel pitch, a focal length or a
    distance wrong. Said before any image is measured, with the field of view the rig gives at the probe."""
    from nerif.geometry import ray_spacing_mm

    filled = [c.name for c, q in zip(cameras, quiet) if q[roi].mean() < FILLED]
    if not filled:
        return []
    step = ray_spacing_mm(cameras, box)
    seen = f"{cameras[0].width * step:.0f} x {cameras[0].height * step:.0f} mm"
    extent = " x ".join(f"{e:.0f}" for e in box.extent_mm)
    msg = (f"the probe box fills the frame of {len(filled)} of {len(cameras)} views ({', '.join(filled[:4])}"
           f"{', ...' if len(filled) > 4 else ''}): the rig gives a field of view of {seen} at the probe centre "
           f"for a box of {extent} mm, so no ray shows the undisturbed background beside the flame. Usual causes: "
           "images binned in the camera while pitch_um is the sensor's own pixel (binned 2 x 2: twice it), the "
           f"focal length or the camera's distance off; check camera: pitch_um, focal_mm and the distances in {source}")
    log.warning("%s", msg)
    return [msg]


def widest_gap_deg(cameras: list[Camera]) -> float:
    """The widest gap [deg] between the cameras' viewing directions, opposite axes counting as one (0 to 180): the
    missing wedge of limited-angle tomography. The axes' azimuths about the normal of the plane they lie nearest
    (the axis the rig turns about), sorted over 180 degrees; 180 for cameras that all look one way."""
    axes = np.stack([np.asarray(c.rotation, dtype=np.float64)[:, 2] for c in cameras])
    normal = rig_axis(cameras)
    u = np.cross(normal, axes[np.argmax(np.linalg.norm(np.cross(normal, axes), axis=1))])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    azimuth = np.sort(np.rad2deg(np.arctan2(axes @ v, axes @ u)) % 180.0)
    return float(np.diff(np.append(azimuth, azimuth[0] + 180.0)).max())


def least_unseen_view(cameras: list[Camera]) -> int:
    """The view to hold out by default: the one whose absence leaves the training views' widest gap of directions
    (:func:`widest_gap_deg`) narrowest, the last of those within :data:`GAP_TIE_DEG` of it (on an arc spread over
    180 degrees every view ties: the last). On an arc narrower than 180 degrees its end views border the missing
    wedge; holding out one of them widens the wedge by a spacing (9 views over 120 degrees: 60 -> 75), an interior
    view leaves it as it was."""
    if len(cameras) < 3:
        return len(cameras) - 1
    gaps = [widest_gap_deg(cameras[:v] + cameras[v + 1:]) for v in range(len(cameras))]
    return max(v for v, g in enumerate(gaps) if g <= min(gaps) + GAP_TIE_DEG)


def missing_wedge(scene) -> list[str]:
    """One sentence (logged, and returned for ``metrics.json``) where the training views leave a gap of viewing
    directions wider than :data:`WEDGE_DEG`: what only those directions would show is not measured, and a hot core's
    peak may read cold by more than its interval allows."""
    gap = widest_gap_deg(scene.cameras)
    if gap <= WEDGE_DEG:
        return []
    msg = (f"the {scene.n_views} training views leave {gap:.0f} degrees of viewing directions unseen (their widest "
           "gap, the missing wedge): structure only those directions would show is not measured, and a hot core's "
           "peak may read cold beyond its interval (with exact deflections, 9 views over 120 degrees read flames' "
           "peaks 7-14 % cold, over 160 degrees 3-5 %)" + (
               "; with more directions unseen than seen, the peak's interval reaches the prior's hottest (the data "
               "bound it no closer)" if gap > UNBOUNDED_DEG else "") + "; cameras spread over 180 degrees close it")
    log.warning("%s", msg)
    return [msg]


def check_sign(scene, prior) -> list[str]:
    """One sentence where the deflections show gas colder than ambient (:func:`hot_evidence`
    above :data:`SIGN`). Where most views agree on it, a flame is hotter, so the reference and distorted images look
    swapped (or the deflections' sign reversed); where the views disagree, the measurement of those views is what
    fails (a flow thrown off by the flame's own light, a shaking camera, an occluder), and the sentence names them.
    Refused unless ``field.prior`` was set (a field that may be colder than ambient: then a warning, returned for
    ``metrics.json``)."""
    evidence = hot_evidence(scene)
    if evidence <= SIGN:
        return []
    per_view = hot_evidence(scene, per_view=True)
    cold = [cam.name for cam, e in zip(scene.cameras, per_view) if e > SIGN]
    hot = [cam.name for cam, e in zip(scene.cameras, per_view) if e < -SIGN]
    seen = f"the deflections point the way gas colder than ambient bends light (hot evidence {evidence:+.2f}; a " \
           "flame gives -0.3 to -1)"
    if len(hot) >= max(1, len(scene.cameras) // 3):
        msg = (f"{seen}, but the views disagree: {', '.join(cold)} show cold gas, {', '.join(hot)} a hot flame; "
               "the displacements of the first look wrong (the flow thrown off by the flame's own light, a "
               "shaking camera, an object in front of the background?): look at their images and the log's "
               "measurement lines")
        fix = "leave those views out (data.heldout) or fix their images"
    else:
        swapped = scene.images is not None
        msg = f"{seen} in {len(cold)} of {len(scene.cameras)} views: " + (
            "the reference and distorted images look swapped" if swapped else "their sign looks reversed")
        fix = "swap them" if swapped else "check the data"
    if prior is None:
        raise ValueError(f"{msg}; {fix}, or for gas that is colder than ambient set field.prior=[a, b] with b above "
                         "its coldest sigma")
    log.warning("%s", msg)
    return [msg]


def ill_posed(scene) -> list[str]:
    """Warnings (logged, and returned for ``metrics.json``) where the data cannot fix a 3-D field: fewer than
    :data:`MIN_DIRECTIONS` distinct viewing directions, or views spanning less than :data:`SPAN_DEG`."""
    n = view_directions(scene.cameras)
    if n < MIN_DIRECTIONS:
        msg = (f"ill-posed: the {scene.n_views} training view(s) look along only {n} distinct direction(s); a 3-D "
               f"field needs at least {MIN_DIRECTIONS}, and the reconstruction is not to be trusted away from what "
               "they see")
    elif (span := view_span_deg(scene.cameras)) < SPAN_DEG:
        msg = (f"ill-posed: the {scene.n_views} training views span only {span:.1f} degrees of viewing directions; "
               f"tomography needs a wide spread ({SPAN_DEG:g} degrees at least), and the reconstruction is not to be "
               "trusted"
               + (" (were the angles given in radians? angles_deg takes degrees)" if span < RADIANS_DEG else ""))
    else:
        return []
    log.warning("%s", msg)
    return [msg]
