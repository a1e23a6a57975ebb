"""Configs: found from the package, one source of defaults, and a new variant is one module plus one yaml."""
import inspect
import sys

import pytest
import torch
import yaml

from nerif.configs import compose, config_dir, group
from nerif.data import DATASETS, PHANTOMS
from nerif.encoders import ENCODERS
from nerif.geometry import RIGS
from nerif.masks import MASKS
from nerif.renderers import SAMPLERS
from nerif.sensing import FLOW, MEASUREMENT, PATTERNS
from nerif.solvers import SOLVERS
from nerif.solvers.data_terms import DATA_TERMS
from tests.helpers import solver, tiny_config

REGISTRIES = {"data": DATASETS, "data_term": DATA_TERMS, "encoder": ENCODERS, "flow": FLOW, "mask": MASKS,
              "measure": MEASUREMENT, "pattern": PATTERNS,
              "phantom": PHANTOMS, "rig": RIGS, "sampler": SAMPLERS, "solver": SOLVERS}
REQUIRED = {"phantom/file": ["phantom.path=x.npy", "phantom.voxel_mm=1.0"], "data/capture": ["data.root=x"],
            "data/transforms": ["data.root=x"]}  # values a config leaves to the user (???)
OPTIONS = [f"{g}/{p.stem}" for g in REGISTRIES for p in sorted((config_dir() / g).glob("*.yaml"))]


def _plain(v):
    return [_plain(x) for x in v] if isinstance(v, (list, tuple)) else v


def test_the_configs_are_the_repository_conf_folder_in_a_checkout():
    assert (config_dir() / "config.yaml").is_file() and (config_dir() / "solver" / "cgls.yaml").is_file()


def test_a_config_is_composed_once_and_again_when_a_file_changes(tmp_path, monkeypatch):
    """compose() keeps a composed config for the same overrides (a copy each call, so a caller's edit stays its
    own) and composes again once a config file changes: never a stale config."""
    import os
    import shutil

    import nerif.configs

    conf = tmp_path / "conf"
    shutil.copytree(config_dir(), conf)
    monkeypatch.setattr(nerif.configs, "config_dir", lambda: conf)
    first = compose(["encoder=hash"])
    first.train.iterations = 7
    assert compose(["encoder=hash"]).train.iterations == 1200  # the caller's edit is not the next call's config
    text = (conf / "config.yaml").read_text()
    (conf / "config.yaml").write_text(text.replace("iterations: 1200 ", "iterations: 1300 ", 1))
    stat = (conf / "config.yaml").stat()  # the same size: only the time tells the edit
    os.utime(conf / "config.yaml", ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))
    assert compose(["encoder=hash"]).train.iterations == 1300


@pytest.mark.parametrize("overrides", [
    ["train.iterations=5", "encoder=frequency", "field.hidden=[32,16]"],
    ["+experiment=paper_phantom5", "train.lr=1e-3", "data.T_max=${train.lr}"],
    ["data=capture", "data.root=x", "~train.image_every", "+train.extra=3", "++loss.new=[1,2]"],
    ["phantom=file", "phantom.path=x.npy", "phantom.voxel_mm=1.0", "rig.n_cameras=3", "solver=cgls"],
])
def test_a_config_kept_for_its_group_choices_takes_the_settings_as_hydra_does(overrides):
    """compose() keeps the config of the group choices and applies the settings to a copy: the very config Hydra
    composes from all the overrides at once (values, +/++/~, lists, interpolations), and the same refusal of a
    setting no block has."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.errors import ConfigCompositionException
    from omegaconf import OmegaConf

    with initialize_config_dir(config_dir=str(config_dir()), version_base=None):
        hydras = hydra_compose("config", overrides=overrides)
    for _ in range(2):  # composed, then kept
        ours = compose(overrides)
        assert OmegaConf.to_yaml(ours) == OmegaConf.to_yaml(hydras)
        assert OmegaConf.is_struct(ours)
    with pytest.raises(ConfigCompositionException, match="train.iteration"):
        compose([*overrides, "train.iteration=3"])


def test_a_config_composed_inside_another_hydra_folder_is_that_folders_not_the_kept_one(tmp_path):
    """A caller that initialised Hydra on its own copy of the configs (or a run with ``hydra.searchpath``) composes
    from those files, whose changes compose() does not watch: never the config it kept from nerif's own folder."""
    import shutil

    from hydra import initialize_config_dir

    ours = compose(["encoder=hash"]).train.iterations
    other = tmp_path / "conf"
    shutil.copytree(config_dir(), other)
    text = (other / "config.yaml").read_text()
    (other / "config.yaml").write_text(text.replace(f"iterations: {ours} ", f"iterations: {ours + 7} ", 1))
    for _ in range(2):  # and again: not kept from the first either (an edit of that folder would go unseen)
        with initialize_config_dir(config_dir=str(other), version_base=None):
            assert compose(["encoder=hash"]).train.iterations == ours + 7
    assert compose(["encoder=hash"]).train.iterations == ours


def test_every_config_group_of_the_registries_has_its_yaml():
    assert len(OPTIONS) >= 20
    for g, reg in REGISTRIES.items():
        assert {p.stem for p in (config_dir() / g).glob("*.yaml")} <= set(reg.names()), g


@pytest.mark.parametrize("option", OPTIONS)
def test_code_defaults_agree_with_the_yaml(option):
    """Every key of the yaml is a parameter of the component it builds, and a parameter's code default equals the
    value the default config gives it. A code default of None stands for 'wired by the config' (a sub-config or an
    environment path, written ``${...}`` in the yaml), never for a competing value."""
    g, name = option.split("/")
    cfg = group(compose([f"{g}={name}", *REQUIRED.get(option, [])]), g)
    raw = yaml.safe_load((config_dir() / g / f"{name}.yaml").read_text())
    entry = REGISTRIES[g].get(cfg.pop("name"))
    params = inspect.signature(entry).parameters
    takes_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
    for key, value in cfg.items():
        assert key in params or takes_any, f"{option}.yaml sets '{key}', which {entry.__name__} does not take"
        p = params.get(key)
        if p is None or p.default is inspect.Parameter.empty:
            continue
        wired = isinstance(raw.get(key), dict) or str(raw.get(key)).startswith("${")
        if p.default is None and wired:
            continue
        assert _plain(p.default) == _plain(value), f"{entry.__name__}({key}={p.default!r}) but {option}.yaml: {value!r}"


def test_run_folders_are_named_by_solver():
    assert compose().solver.label == "hash-discrete"
    assert compose(["encoder=frequency", "grad=hybrid"]).solver.label == "frequency-hybrid"
    assert compose(["solver=cgls", "solver.regularizer=tv"]).solver.label == "cgls-tv"


def test_the_seed_reaches_every_solver():
    for s in ("nerif", "cgls"):
        assert group(compose([f"solver={s}", "seed=7"]), "solver")["seed"] == 7


TOY = '''
import torch
from torch import nn

from nerif.encoders.base import ENCODERS


@ENCODERS.register("toy")
class Squares(nn.Module):
    """(N, 3) -> (N, 6): the coordinates and their powers."""

    def __init__(self, power: int = 2):
        super().__init__()
        self.power, self.out_dim = power, 6

    def forward(self, x):
        return torch.cat([x, x**self.power], -1)
'''


def test_a_new_encoder_is_one_module_and_one_yaml(tmp_path, monkeypatch):
    """A module in the encoders package and a yaml in conf/encoder/ (here: a folder on Hydra's search path) are all
    a new encoder takes: it is found, built from its config and trained, with no other edit."""
    import nerif.encoders
    from nerif.data import DATASETS

    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "toy.py").write_text(TOY)
    (tmp_path / "conf" / "encoder").mkdir(parents=True)
    (tmp_path / "conf" / "encoder" / "toy.yaml").write_text("name: toy\npower: 3\n")
    ENCODERS.discover()  # every encoder registered before the copy: one first imported here would be lost after
    monkeypatch.setattr(nerif.encoders, "__path__", [*nerif.encoders.__path__, str(tmp_path / "pkg")])
    monkeypatch.setattr(ENCODERS, "_entries", dict(ENCODERS._entries))
    try:
        cfg = tiny_config("encoder=toy", f"hydra.searchpath=[file://{tmp_path / 'conf'}]")
        scene = DATASETS.build(group(cfg, "data"))
        s = solver(cfg, scene)
        assert type(s.field.encoder).__name__ == "Squares" and s.field.encoder.power == 3
        x = torch.tensor([[0.5, -0.5, 2.0]])
        torch.testing.assert_close(s.field.encoder(x), torch.tensor([[0.5, -0.5, 2.0, 0.125, -0.125, 8.0]]))
        before = [p.detach().clone() for p in s.field.parameters()]
        assert torch.isfinite(torch.tensor(s.step()["loss"]))
        assert any(not torch.equal(a, b) for a, b in zip(before, s.field.parameters()))
    finally:
        sys.modules.pop("nerif.encoders.toy", None)
