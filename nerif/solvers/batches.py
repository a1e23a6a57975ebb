"""Training batches of rays: which views an iteration draws from, and which rays of each, inside and outside the
view's 2-D mask."""
from __future__ import annotations

import copy
from typing import Optional, Sequence

import torch

from nerif.data import Scene


def check_views_per_batch(k) -> None:
    """``train.views_per_batch``: a number of views (at least 1) or ``all``; one sentence otherwise."""
    if not (k == "all" or (isinstance(k, int) and not isinstance(k, bool) and k >= 1)):
        raise ValueError(f"train.views_per_batch must be a number of views (at least 1) or 'all', got {k!r}")


class RayBatcher:
    """Draws each iteration's rays evenly from its views (or, as in the paper, from one view per iteration,
    views cycled), with ``outside_fraction`` of each view's rays outside its 2-D mask.

    Args:
        scene: the training scene.
        inside: per view, the scene indices of the rays inside its 2-D mask (None: every ray).
        rays_per_batch: rays per iteration, split evenly over the batch's views.
        views_per_batch: views per batch, a number (cycled) or ``all``.
        outside_fraction: share of each view's rays drawn outside its 2-D mask, within [0, 1).
        generator: the random stream of the draws (the solver's, so that a checkpoint restores it).
        allowed: (N,) bool, the rays that may be drawn at all (default: every ray).
    """

    def __init__(self, scene: Scene, inside: Optional[Sequence[torch.Tensor]], rays_per_batch: int,
                 views_per_batch, outside_fraction: float, generator: torch.Generator,
                 allowed: Optional[torch.Tensor] = None):
        self.scene, self.generator = scene, generator
        self.rays_per_batch, self.views_per_batch = int(rays_per_batch), views_per_batch
        self.outside_fraction = float(outside_fraction)
        self.pools = self._pools(scene, inside, allowed)
        self.drawn = list(range(scene.n_views))  # the views batches are drawn from

    @staticmethod
    def _pools(scene: Scene, inside, allowed=None) -> list[tuple[torch.Tensor, Optional[torch.Tensor]]]:
        """Per view: (rays inside its 2-D mask, rays outside it or None), as scene indices; only rays where
        ``allowed`` (N,) bool is True, when given."""
        pools = []
        for v in range(scene.n_views):
            sl = scene.view_slice(v)
            every = torch.arange(sl.start, sl.stop, device=scene.dirs.device)
            mine = inside[v] if inside is not None else None
            if allowed is not None:
                every = every[allowed[every]]
                mine = None if mine is None else mine[allowed[mine]]
                if len(every) == 0:
                    raise ValueError(f"{scene.cameras[v].name}: none of its rays can be drawn for training")
            if mine is None or len(mine) == 0:  # no mask, or an empty one (warned when it was built)
                pools.append((every, None))
                continue
            outside = every[~torch.isin(every, mine)]
            pools.append((mine, outside if len(outside) else None))
        return pools

    def inside(self) -> torch.Tensor:
        """Scene indices of every ray inside a 2-D mask (every ray of a view without one)."""
        return torch.cat([pool[0] for pool in self.pools])

    def draw(self, view: int, n: int) -> torch.Tensor:
        """Scene indices of ``n`` random rays of ``view``: inside its 2-D mask, and ``round(outside_fraction n)``
        of them outside it."""
        inside, outside = self.pools[view]
        n_out = int(round(self.outside_fraction * n)) if outside is not None else 0
        parts = [(inside, n - n_out)] + ([(outside, n_out)] if n_out else [])
        device = self.scene.dirs.device
        return torch.cat([pool[torch.randint(len(pool), (m,), generator=self.generator, device=device)]
                          for pool, m in parts])

    def of_views(self, views: Sequence[int], generator: Optional[torch.Generator] = None) -> "RayBatcher":
        """The same draws from ``views`` only (scene view indices; an ensemble member that leaves the others out),
        from ``generator`` where given (else this one's stream)."""
        out = copy.copy(self)
        out.drawn = sorted({int(v) for v in views})
        out.generator = self.generator if generator is None else generator
        return out

    def views(self, iteration: int) -> list[int]:
        """The views of iteration ``iteration``'s batch: the next ``views_per_batch`` views, cycled, so that every
        view is seen equally often (with ``all``, every view in every batch)."""
        n = len(self.drawn)
        k = n if self.views_per_batch == "all" else min(self.views_per_batch, n)
        return [self.drawn[(iteration * k + j) % n] for j in range(k)]

    def __call__(self, iteration: int) -> torch.Tensor:
        """Scene indices of iteration ``iteration``'s ``rays_per_batch`` rays, split evenly over its views."""
        views = self.views(iteration)
        share, extra = divmod(self.rays_per_batch, len(views))
        counts = [share + (j < extra) for j in range(len(views))]
        return torch.cat([self.draw(v, c) for v, c in zip(views, counts) if c])
