"""Training batches (:mod:`nerif.solvers.batches`): rays split evenly over a batch's views, the share outside each
view's 2-D mask, views cycled equally often, rays that may not be drawn never drawn, and bad settings one sentence."""
from types import SimpleNamespace

import pytest
import torch

from nerif.solvers.batches import RayBatcher, check_views_per_batch

COUNTS = (40, 60, 50, 30, 70)  # rays of each of 5 views


def scene():
    starts = torch.tensor([0, *torch.tensor(COUNTS).cumsum(0).tolist()])
    return SimpleNamespace(n_views=len(COUNTS), dirs=torch.zeros(int(starts[-1]), 3),
                           view_slice=lambda v: slice(int(starts[v]), int(starts[v + 1])),
                           cameras=[SimpleNamespace(name=f"camera {v}") for v in range(len(COUNTS))], starts=starts)


def view_of(sc, idx):
    return torch.searchsorted(sc.starts, idx, right=True) - 1


def masks(sc):
    """Per view, its first half of rays inside the 2-D mask."""
    return [torch.arange(sc.starts[v], sc.starts[v] + n // 2) for v, n in enumerate(COUNTS)]


def test_a_batch_splits_its_rays_evenly_over_every_view_and_draws_the_outside_share():
    sc = scene()
    batch = RayBatcher(sc, masks(sc), rays_per_batch=103, views_per_batch="all", outside_fraction=0.2,
                       generator=torch.Generator().manual_seed(0))
    idx = batch(0)
    per_view = torch.bincount(view_of(sc, idx), minlength=5)
    assert len(idx) == 103 and per_view.tolist() == [21, 21, 21, 20, 20]  # 103 = 5 x 20 + 3
    inside = torch.isin(idx, torch.cat(masks(sc)))
    for v in range(5):  # round(0.2 x 21) = 4, round(0.2 x 20) = 4 outside each view's mask
        assert int((~inside[view_of(sc, idx) == v]).sum()) == 4
    assert torch.equal(batch.inside().sort().values, torch.cat(masks(sc)))


def test_views_are_cycled_so_that_each_is_seen_equally_often():
    sc = scene()
    batch = RayBatcher(sc, None, rays_per_batch=10, views_per_batch=2, outside_fraction=0.0,
                       generator=torch.Generator().manual_seed(0))
    seen = [v for it in range(5) for v in batch.views(it)]
    assert sorted(seen) == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
    assert set(view_of(sc, batch(1)).tolist()) == {2, 3}
    member = batch.of_views([4, 1], torch.Generator().manual_seed(1))
    assert member.views(0) == [1, 4] and set(view_of(sc, member(0)).tolist()) <= {1, 4}
    assert batch.drawn == [0, 1, 2, 3, 4]  # the member's choice leaves the batcher it came from alone


def test_rays_that_may_not_be_drawn_never_are_and_a_view_left_without_rays_is_named():
    sc = scene()
    allowed = torch.ones(len(sc.dirs), dtype=torch.bool)
    allowed[::2] = False
    batch = RayBatcher(sc, masks(sc), rays_per_batch=500, views_per_batch="all", outside_fraction=0.3,
                       generator=torch.Generator().manual_seed(0), allowed=allowed)
    assert bool(allowed[batch(0)].all())
    allowed[sc.view_slice(3)] = False
    with pytest.raises(ValueError, match="camera 3: none of its rays can be drawn for training"):
        RayBatcher(sc, None, 10, "all", 0.0, torch.Generator(), allowed=allowed)


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "some", None])
def test_views_per_batch_is_a_number_of_views_or_all(bad):
    check_views_per_batch("all")
    check_views_per_batch(3)
    with pytest.raises(ValueError, match="train.views_per_batch must be a number of views"):
        check_views_per_batch(bad)
