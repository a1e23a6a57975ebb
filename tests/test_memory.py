"""Memory estimates before any work: a setting that cannot fit is refused in one sentence naming its key."""
import pytest
import torch

from nerif.configs import compose
from nerif.memory import check_memory, estimates


def total(*overrides) -> float:
    return sum(b for _, _, b in estimates(compose(list(overrides))))


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
    check_memory(compose([]), torch.device("cpu"))  # the default fits
    with pytest.raises(ValueError, match=f"GiB free on cpu: {key}$"):
        check_memory(compose([override]), torch.device("cpu"))

