"""Where the configs are, and composing one without the command line.

The configs live in ``conf/`` at the top of the repository (``conf/config.yaml`` and one folder per config
group). A wheel carries them inside the package as ``nerif/conf`` (see ``setup.py``), so an installed nerif finds
them from any folder; a source checkout or an editable install reads the repository's ``conf/``.
"""
from __future__ import annotations

import copy
import math
import os
from pathlib import Path
from typing import Mapping, Optional, Sequence

from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

_PACKAGE = Path(__file__).resolve().parent


def config_dir() -> Path:
    """The folder holding ``config.yaml``: the package's own copy (installed wheel), else the repository's."""
    for folder in (_PACKAGE / "conf", _PACKAGE.parent / "conf"):
        if (folder / "config.yaml").is_file():
            return folder
    raise FileNotFoundError(f"nerif's configs are missing: neither {_PACKAGE / 'conf'} nor {_PACKAGE.parent / 'conf'} "
                            "holds config.yaml (reinstall nerif)")


_COMPOSED: dict = {}  # (config name, group choices, folders) -> their config, from the files as _FILES saw them
_FILES: list = [None]  # the config files' paths, sizes and times when _COMPOSED was filled


def _folders(root: Path) -> Optional[tuple]:
    """The folders of config files a compose reads now, as a cache key: this package's alone (a caller that
    initialised Hydra elsewhere composes from its own folders), or None where Hydra also searches a folder of files
    this module does not watch (another ``initialize_config_dir``, a run's ``hydra.searchpath``): not cached."""
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.hydra_config import HydraConfig

    hydra = GlobalHydra.instance()
    if not hydra.is_initialized():
        return (str(root),)
    files = tuple(s.path for s in hydra.config_loader().get_sources() if s.scheme() == "file")
    searched = HydraConfig.initialized() and bool(HydraConfig.get().searchpath)
    return files if files == (str(root),) and not searched else None


def _split(overrides: Sequence[str], root: Path) -> Optional[tuple[list[str], list]]:
    """``overrides`` as Hydra splits them: the config-group choices (``data=capture``, ``+experiment=...``), which
    decide the files a config is composed of, and the settings (``train.iterations=5``, ``+key=1``), which Hydra
    applies to that config afterwards, parsed. None where Hydra is to compose them itself: an override of Hydra's
    own, a sweep, a package, or one it cannot read (its error is Hydra's to say)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    try:
        parsed = OverridesParser.create().parse_overrides(list(overrides))
    except Exception:
        return None
    choices, settings = [], []
    for line, o in zip(overrides, parsed):
        if o.key_or_group.startswith("hydra") or o.is_sweep_override() or o.package is not None:
            return None
        if (root / o.key_or_group).is_dir() and not isinstance(o.value(), dict):  # Hydra's test of a choice
            choices.append(line)
        else:
            settings.append(o)
    return choices, settings


def compose(overrides: Sequence[str] = (), config_name: str = "config") -> DictConfig:
    """The config ``python -m nerif OVERRIDES`` would run with (without Hydra's run folder). Composing reads every
    yaml (0.2-0.4 s), so the config of the same group choices is composed once a process while no config file
    changes, and each call applies its settings to a copy of it, as Hydra applies them after composing. Inside an
    initialised Hydra (a run), from its search path; composed each time where that, or an override, adds a folder
    whose files are not watched."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra._internal.config_loader_impl import ConfigLoaderImpl
    from hydra.core.global_hydra import GlobalHydra

    root = config_dir()
    files = [(str(p), p.stat().st_mtime_ns, p.stat().st_size) for p in sorted(root.rglob("*.yaml"))]
    if files != _FILES[0]:  # a config file changed (or another folder): nothing composed before holds
        _COMPOSED.clear()
        _FILES[0] = files

    def composed(lines: list[str]) -> DictConfig:
        if GlobalHydra.instance().is_initialized():  # inside a run: Hydra's own search path
            return hydra_compose(config_name, overrides=lines)
        with initialize_config_dir(config_dir=str(root), version_base=None):
            return hydra_compose(config_name, overrides=lines)

    folders = _folders(root)
    split = _split(overrides, root) if folders is not None else None
    if split is None:
        return composed(list(overrides))
    choices, settings = split
    key = (config_name, tuple(choices), folders)
    if key not in _COMPOSED:
        _COMPOSED[key] = composed(choices)
    cfg = copy.deepcopy(_COMPOSED[key])
    ConfigLoaderImpl._apply_overrides_to_config(settings, cfg)  # what Hydra's compose does after the files
    return cfg


def group(cfg: DictConfig, key: str) -> dict:
    """One config group, resolved, as plain containers: what a registry builds the component from."""
    return OmegaConf.to_container(cfg[key], resolve=True)


def missing_keys(cfg: DictConfig, prefix: str = "") -> list[str]:
    """Dotted keys of the values left unset (``???``) in ``cfg``, Hydra's own settings left out."""
    out = []
    for key in cfg.keys():
        if not prefix and key == "hydra":
            continue
        path = f"{prefix}{key}"
        if OmegaConf.is_missing(cfg, key):
            out.append(path)
        elif OmegaConf.is_interpolation(cfg, key):
            continue  # a group wired into another one: reported under its own name
        elif isinstance(cfg[key], DictConfig):
            out += missing_keys(cfg[key], f"{path}.")
    return out


def stray_keys(cfg: DictConfig) -> list[tuple[str, list[str]]]:
    """Keys of the plain blocks of ``config.yaml`` (``train``, ``loss``, ``field``, ...: not config groups, whose
    settings their registries check) and of its top level that ``config.yaml`` does not define (a ``+key=value``
    or a misspelling), each with the block's own keys."""
    base = OmegaConf.load(config_dir() / "config.yaml")
    groups = {next(iter(d)) for d in base.defaults if isinstance(d, (dict, DictConfig))}
    known_top = set(base.keys()) | groups | {"hydra", "defaults", "experiment"}
    out = [(k, sorted(known_top - {"defaults", "hydra"})) for k in cfg.keys() if k not in known_top]
    for block in base.keys():
        if block not in ("defaults", "hydra") and isinstance(base[block], DictConfig) and block in cfg:
            known = list(base[block].keys())
            out += [(f"{block}.{k}", known) for k in cfg[block].keys() if k not in known]
    return out


def check_complete(cfg: DictConfig) -> None:
    """One sentence naming every required value left unset (e.g. ``phantom.path``) or a key no block takes
    (e.g. ``+train.iteration=5``)."""
    stray = stray_keys(cfg)
    if stray:
        import difflib

        key, known = stray[0]
        near = difflib.get_close_matches(key.rsplit(".", 1)[-1], known, n=1)
        where = key.rsplit(".", 1)[0] + "." if "." in key else ""
        raise ValueError(f"{', '.join(k for k, _ in stray)}: not a setting nerif knows"
                         + (f" (did you mean {where}{near[0]}?)" if near else "")
                         + f"; the settings{' of ' + where[:-1] if where else ''}: {', '.join(known)}")
    missing = missing_keys(cfg)
    if missing:
        raise ValueError(f"{', '.join(missing)} must be set: give {'it' if len(missing) == 1 else 'them'} on the "
                         f"command line, e.g. {missing[0]}=...")


def group_choices(overrides: Sequence[str]) -> list[str]:
    """The config-group choices among command-line ``overrides`` (``data=capture``, ``+experiment=...``): the
    config a setting's kind is read from (:func:`check_kinds`) is composed of these alone."""
    groups = {p.name for p in config_dir().iterdir() if p.is_dir()}
    return [o for o in overrides if o.lstrip("+~").split("=")[0] in groups]


WORDS = ("auto", "all")  # words a numeric setting may take instead (threads=auto, train.views_per_batch=all)


def _kind(default, value) -> Optional[str]:
    """What ``value`` must be, as its setting's ``default`` shows (a number, true or false, a list), where it is
    not; None where it is, or where the default shows no kind (null, a word)."""
    def number(x) -> bool:
        return not isinstance(x, bool) and isinstance(x, (int, float))

    if isinstance(default, bool):
        return None if isinstance(value, bool) else "true or false"
    if number(default):
        return None if number(value) or value is None or value in WORDS else "a number"
    if isinstance(default, list):
        if not isinstance(value, list):
            return "a list"
        if default and all(number(x) for x in default) and not all(number(x) for x in value):
            return "a list of numbers"
    return None


def check_kinds(cfg: DictConfig, defaults: DictConfig, overrides: Sequence[str]) -> None:
    """One sentence for a command-line setting (``key=value`` of ``overrides``) whose value in ``cfg`` is not of
    the kind of its value in ``defaults`` (the config of the same config-group choices without the settings): a
    word where a number goes (``rig.n_cameras=abc``), a number where a list goes (``field.hidden=64``). A setting
    whose default is null or a word is left to the component that reads it."""
    for key in dict.fromkeys(o.lstrip("+~").partition("=")[0] for o in overrides if "=" in o):
        if key.startswith("hydra") or OmegaConf.select(defaults, key, default=None) is None:
            continue
        default = OmegaConf.select(defaults, key)
        value = OmegaConf.select(cfg, key)
        plain = [OmegaConf.to_container(x) if isinstance(x, (DictConfig, ListConfig)) else x for x in (default, value)]
        need = _kind(*plain)
        if need:
            raise ValueError(f"{key}={plain[1]}: {need} (its default: {plain[0]})")


def unknown_override(args: Sequence[str]) -> Optional[str]:
    """One sentence for the first command-line override that names a config-group option or a setting nerif does
    not have (``encoder=hsh``, ``train.iteration=300``, ``field.hash_level=4``), with the nearest it has; None.
    ``+key=value`` adds a key on purpose (:func:`check_complete` judges it); Hydra's own settings (``hydra.*``) are
    Hydra's to check."""
    import difflib

    from hydra.core.override_parser.overrides_parser import OverridesParser

    def nearest(word: str, known) -> Optional[str]:
        near = difflib.get_close_matches(word, sorted(known), n=1, cutoff=0.6)
        return near[0] if near else None

    parser = OverridesParser.create()
    try:
        parsed = parser.parse_overrides([a for a in args if "=" in a and not a.startswith("-")])
    except Exception:  # a value Hydra cannot read: said elsewhere
        return None
    root = config_dir()
    groups = {p.name for p in root.iterdir() if p.is_dir() and p.name != "hydra"}
    settings, choices = [], []
    for o in parsed:
        key = o.key_or_group
        if key.startswith("hydra") or o.is_delete():
            continue
        if key in groups:
            options = {p.stem for p in (root / key).glob("*.yaml")}
            values = list(o.sweep_string_iterator()) if o.is_sweep_override() else [o.get_value_element_as_str()]
            choices.append(f"{'+' if o.is_add() else ''}{key}={values[0]}")  # a sweep's first: its keys are alike
            for value in values:
                if value not in options:
                    near = nearest(value, options)
                    return (f"{key}={value}: {key} has no option {value!r}"
                            + (f" (did you mean {key}={near}?)" if near else "")
                            + f"; its options: {', '.join(sorted(options))}")
        elif not o.is_add() and not o.is_force_add():
            settings.append(key)
    if not settings:
        return None
    try:
        cfg = compose(choices)
    except Exception:  # choices Hydra refuses (a group not in the defaults given without "+"): Hydra's to say
        return None
    for key in settings:
        node, path = cfg, []
        parts = key.split(".")
        for i, part in enumerate(parts):
            if not isinstance(node, DictConfig) or part not in node.keys():  # `in` is False for a value left ???
                known = list(node.keys()) if isinstance(node, DictConfig) else []
                where = ".".join(path)
                near = nearest(part, [k for k in known if k != "hydra"])
                guess = ".".join([*path, str(near), *parts[i + 1:]])
                hint = f" (did you mean {guess}?)" if near else (
                    f"; {where or 'the top level'} has {', '.join(str(k) for k in known if k != 'hydra')}"
                    if known else "")
                return f"{key}: not a setting nerif knows{hint}"
            node, path = None if OmegaConf.is_missing(node, part) else node[part], path + [part]  # ???: a leaf
    return None


def _number(v, whole: bool = False) -> bool:
    ok = isinstance(v, int) if whole else isinstance(v, (int, float))
    return ok and not isinstance(v, bool) and math.isfinite(v)


def check_train(train: Mapping, seed) -> None:
    """One sentence, naming the key, for a ``train`` setting no run can take (checked before any data are made)."""
    def key(name: str, what: str, ok: bool) -> None:
        if not ok:
            raise ValueError(f"train.{name}={train[name]!r}: {what}")

    for name in ("iterations", "eval_every", "checkpoint_every", "image_every", "rays_per_batch", "stop_patience"):
        key(name, "a whole number of at least 1", _number(train[name], whole=True) and train[name] >= 1)
    key("init_iterations", "a whole number of at least 0",
        _number(train["init_iterations"], True) and train["init_iterations"] >= 0)
    key("lr", "the peak learning rate, a positive number", _number(train["lr"]) and train["lr"] > 0)
    key("lr_min", f"the learning rate's floor, within [0, train.lr = {train['lr']}]",
        _number(train["lr_min"]) and 0 <= train["lr_min"] <= (train["lr"] if _number(train["lr"]) else 0))
    betas = train["betas"]
    key("betas", "Adam's two decay rates, each within [0, 1)", isinstance(betas, (list, tuple)) and len(betas) == 2
        and all(_number(b) and 0 <= b < 1 for b in betas))
    key("eps", "Adam's denominator floor, a positive number", _number(train["eps"]) and train["eps"] > 0)
    s = train["checkpoint_every_s"]
    key("checkpoint_every_s", "seconds between checkpoints, a positive number or null",
        s is None or (_number(s) and s > 0))
    if not _number(seed, whole=True):
        raise ValueError(f"seed={seed!r}: a whole number")


def check_figures(cfg: DictConfig) -> None:
    """``figures`` (set, or read from the environment's ``NERIF_FIGURES``) is true or false: else one sentence."""
    try:
        value = cfg.figures
    except OmegaConfBaseException:  # NERIF_FIGURES not a value at all (e.g. '[1,')
        value = os.environ.get("NERIF_FIGURES")
    if not isinstance(value, bool):
        raise ValueError(f"figures={value!r}: true (the results' pictures drawn) or false (the data files alone), "
                         "as a setting or in the environment's NERIF_FIGURES")


def check_settings(cfg: DictConfig) -> None:
    """One sentence for a setting no run can take, read from the config alone (no torch, no data): ``figures``,
    a required value left unset or a key no block takes (:func:`check_complete`), the ``train`` block and the
    seed (:func:`check_train`). The command line checks them before the seconds of importing torch."""
    check_figures(cfg)
    check_complete(cfg)
    check_train(group(cfg, "train"), cfg.seed)
