"""Memory estimates before any work: a setting that cannot fit is refused in one sentence naming its key."""
import pytest
import torch

from nerif.app import allocations
from nerif.configs import compose
from nerif.memory import check_memory


def total(*overrides) -> float:
    return sum(b for _, _, b in allocations(compose(list(overrides))))


def test_estimates_grow_as_the_allocations_they_stand_for():
    base = total()
    assert 1e7 < base < 2**30  # the default run: tens to hundreds of MB
    # the occupancy grid is R^3 cells, the rendering grid supersample^3 voxels, a step's samples rays x samples
    grid = {r: total(f"field.occupancy_resolution={r}") for r in (64, 128, 256)}
    assert (grid[256] - grid[128]) / (grid[128] - grid[64]) == pytest.approx(8.0)  # R^3
    fine = {s: total(f"data.render_supersample={s}") for s in (1, 2, 4)}
    assert (fine[4] - fine[2]) / (fine[2] - fine[1]) == pytest.approx(8.0)  # (s^3: 64 - 8) / (8 - 1)
    step = total("train.rays_per_batch=512") - base
    assert step == pytest.approx(total("sampler.samples_per_ray=64") - base, rel=1e-6)


@pytest.mark.parametrize("override, key", [
    ("field.occupancy_resolution=2000", "lower field.occupancy_resolution"),
    ("field.hidden=[100000,100000]", "lower field.hidden"),
    ("data.render_supersample=32", "lower data.render_supersample"),
    ("train.rays_per_batch=5000000", "lower train.rays_per_batch or sampler.samples_per_ray"),
    ("sampler.samples_per_ray=200000", "lower train.rays_per_batch or sampler.samples_per_ray"),
])
def test_a_run_that_cannot_fit_is_refused_naming_the_key(monkeypatch, override, key):
    """Issue 28: each of these ran for seconds to minutes and ended in a MemoryError (one at 6.4 GB)."""
    monkeypatch.setattr("nerif.memory.available_bytes", lambda device: 16 * 2.0**30)
    check_memory(allocations(compose([])), torch.device("cpu"))  # the default fits
    with pytest.raises(ValueError, match=f"GiB free on cpu: {key}$"):
        check_memory(allocations(compose([override])), torch.device("cpu"))



def test_a_captures_probe_grid_is_read_from_its_rig_file(tmp_path, monkeypatch):
    """Issue 38: a probe grid of [600, 1000, 600] in rig.yaml (a zero too many) took 8 GiB in 23 s: the estimate did
    not read the rig's grid. It reads it now, and the refusal names the key and the file."""
    import yaml

    (tmp_path / "rig.yaml").write_text(yaml.safe_dump({
        "format": "nerif-capture", "version": 1, "roi_px": [0, 0, 64, 64],
        "camera": {"focal_mm": 105.0, "pitch_um": 20.0, "sensor_px": [64, 64], "f_number": 32.0,
                   "camera_to_centre_mm": 800.0, "camera_to_background_mm": 1600.0},
        "views": {"angles_deg": [0, 60, 120], "references": "r.png", "images": ["a.png", "b.png", "c.png"]},
        "probe": {"shape": [600, 1000, 600], "voxel_mm": 0.1}, "ambient": {"T0": 296.0, "n0": 1.00027}}))
    cfg = compose(["data=capture", f"data.root={tmp_path}"])
    grid = [(key, b) for what, key, b in allocations(cfg) if what == "the probe grid's volumes"]
    assert grid == [(f"probe.shape in {tmp_path / 'rig.yaml'}", pytest.approx(600 * 1000 * 600 * 96))]
    monkeypatch.setattr("nerif.memory.available_bytes", lambda device: 16 * 2.0**30)
    with pytest.raises(ValueError, match=f"lower probe.shape in {tmp_path / 'rig.yaml'}$"):
        check_memory(allocations(cfg), torch.device("cpu"))


def test_a_captures_images_count_before_any_work(tmp_path, monkeypatch):
    """Issue 39: a capture's images take about 24 bytes a pixel over a run (6.0 GiB at 10 views of 25 megapixels),
    and 4 x 3 more where the image term reads the references on a grid twice as fine (the band-limited default,
    issue 56). Nine views of 20000 x 20000 px (3.6e9 pixels) are refused before any image is read, naming what sets
    them."""
    import yaml

    (tmp_path / "rig.yaml").write_text(yaml.safe_dump({
        "format": "nerif-capture", "version": 1, "roi_px": [0, 0, 20000, 20000],
        "camera": {"focal_mm": 105.0, "pitch_um": 5.0, "sensor_px": [20000, 20000], "f_number": 32.0,
                   "camera_to_centre_mm": 800.0, "camera_to_background_mm": 1600.0},
        "views": {"angles_deg": [20 * k for k in range(9)], "references": "r.png",
                  "images": [f"d{k}.png" for k in range(9)]},
        "probe": {"shape": [60, 100, 60], "voxel_mm": 1.0}, "ambient": {"T0": 296.0, "n0": 1.00027}}))
    for read, per_pixel in (("bicubic", 24), ("bandlimited", 24 + 4 * 3)):
        cfg = compose(["data=capture", f"data.root={tmp_path}", f"data_term.interpolation={read}"])
        part = [(b, what) for name, what, b in allocations(cfg) if name == "the images"]
        assert part == [(pytest.approx(3.6e9 * per_pixel), pytest.approx(part[0][1]))]
        assert str(tmp_path / "rig.yaml") in part[0][1]
    monkeypatch.setattr("nerif.memory.available_bytes", lambda device: 16 * 2.0**30)
    with pytest.raises(ValueError, match="the images alone 121 GiB.*lower the views in .*rig.yaml \\(fewer views"):
        check_memory(allocations(cfg), torch.device("cpu"))
