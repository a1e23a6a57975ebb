"""The mask registry and what every mask builder returns (:mod:`nerif.masks.base`)."""
from pathlib import Path

import torch

from nerif.configs import group
from nerif.data import DATASETS
from nerif.masks import MASKS, Masks
from nerif.solvers.batches import RayBatcher
from tests.helpers import tiny_config

CONF = Path(__file__).resolve().parents[1] / "conf" / "mask"


def test_every_mask_config_has_its_builder_and_every_builder_its_config():
    assert sorted(MASKS.names()) == sorted(p.stem for p in CONF.glob("*.yaml")) == ["2d", "3d", "none"]


def test_no_mask_trains_on_every_ray_with_no_gate():
    cfg = tiny_config("mask=none")
    scene = DATASETS.build(group(cfg, "data"))
    masks = MASKS.build(group(cfg, "mask"), scene=scene)
    assert isinstance(masks, Masks) and (masks.images, masks.inside, masks.gate, masks.volume) == (None,) * 4
    batches = RayBatcher(scene, masks.inside, 10_000, "all", 0.0, torch.Generator().manual_seed(0))
    assert len(batches.inside()) == len(scene.dirs)  # the pool training draws from: every ray
