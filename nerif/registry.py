"""Name -> component registries: every interchangeable part is chosen by name from its config group.

A registry belongs to a package and holds what the modules of that package register. Its entries are found by
importing every module of the package the first time a name is looked up (and again when a name is missing),
so adding a variant is one module that registers it plus one yaml in ``conf/<group>/``, with no other edit.

Every component is built the same way, from its config group (a mapping whose ``name`` picks the entry; the
other keys are its keyword arguments) plus the run-time objects it needs::

    ENCODERS.build(cfg.encoder)
    MASKS.build(cfg.mask, scene=scene)
"""
from __future__ import annotations

import importlib
import inspect
import pkgutil
from typing import Any, Callable, Mapping, Optional


class UnknownComponent(ValueError):
    """A config names a component that no module registers (bad input, reported as one sentence)."""


class Registry:
    """A family of components (encoders, samplers, ...) built by name.

    Args:
        family: what the entries are, for messages (``"encoder"``).
        package: the package whose modules register the entries (``"nerif.encoders"``); None: only what is
            registered explicitly.

    >>> ENCODERS = Registry("encoder", package="nerif.encoders")
    >>> @ENCODERS.register("none")
    ... class Identity: ...
    """

    def __init__(self, family: str, package: Optional[str] = None):
        self.family, self.package = family, package
        self._entries: dict[str, Callable[..., Any]] = {}
        self._hints: dict[str, dict[str, str]] = {}

    def register(self, name: str, hints: Optional[Mapping[str, str]] = None,
                 allocations: Optional[Callable[[Mapping], list]] = None):
        """Decorator registering a component as ``name``; ``hints``: settings users may look for here, mapped to
        where they really are (``{"binning": "rig.binning"}``), for the message that refuses them;
        ``allocations``: what the component will allocate in a run (:meth:`allocations`), for an entry that cannot
        say it itself (a function; a class says it with a static method ``allocations(cfg)``)."""
        def decorator(obj):
            if name in self._entries:
                raise ValueError(f"{self.family} '{name}' is registered twice")
            if allocations is not None:
                obj.allocations = allocations
            self._entries[name] = obj
            self._hints[name] = dict(hints or {})
            return obj

        return decorator

    def discover(self) -> None:
        """Import every module of the registry's package (each registers its entries on import)."""
        if self.package is None:
            return
        pkg = importlib.import_module(self.package)
        for info in pkgutil.walk_packages(pkg.__path__, prefix=f"{self.package}."):
            importlib.import_module(info.name)

    def names(self) -> list[str]:
        self.discover()
        return sorted(self._entries)

    def get(self, name: str) -> Callable[..., Any]:
        if name not in self._entries:
            self.discover()
        if name not in self._entries:
            raise UnknownComponent(
                f"unknown {self.family} '{name}'; registered {self.family}s: {', '.join(self.names())}"
            )
        return self._entries[name]

    def build(self, cfg: Mapping[str, Any], **extra: Any) -> Any:
        """Build from a config mapping whose ``name`` picks the entry; the other keys are keyword arguments, and
        ``extra`` the run-time objects the entry needs (a scene, an image, ...)."""
        params = dict(cfg)
        name = params.pop("name", None)
        if name is None:
            raise UnknownComponent(f"the {self.family} config has no 'name'; choose one of: {', '.join(self.names())}")
        entry = self.get(name)
        self._check_settings(name, entry, params)
        return entry(**params, **extra)

    def allocations(self, cfg: Mapping[str, Any], group: str) -> list:
        """What the entry that the run's config ``cfg`` picks in its ``group`` declares it will allocate:
        ``(what, the key that sets it, bytes)`` of its largest allocations (:mod:`nerif.memory`), none where it
        declares nothing."""
        declared = getattr(self.get(cfg[group]["name"]), "allocations", None)
        return list(declared(cfg)) if declared is not None else []

    def _check_settings(self, name: str, entry: Callable[..., Any], params: Mapping[str, Any]) -> None:
        """One sentence for a setting the entry does not take (a stray ``+key=value`` or a misspelling)."""
        try:
            sig = inspect.signature(entry)
        except (TypeError, ValueError):
            return
        if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
            return
        stray = [k for k in params if k not in sig.parameters]
        if stray:
            hints = self._hints.get(name, {})
            where = "".join(f" (for {k}, use {hints[k]})" for k in stray if k in hints)
            known = [k for k, p in sig.parameters.items() if p.kind is not p.VAR_POSITIONAL]
            raise ValueError(f"{', '.join(stray)}: not a setting of the {self.family} '{name}'{where}; its settings: "
                             f"{', '.join(known)}")

    def __contains__(self, name: str) -> bool:
        if name not in self._entries:
            self.discover()
        return name in self._entries
