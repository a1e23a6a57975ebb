"""Name -> class registries: every interchangeable component is chosen by name from its config group."""
from __future__ import annotations

from typing import Any, Callable, Mapping


class Registry:
    """A family of components (encoders, samplers, ...) built by name.

    >>> ENCODERS = Registry("encoder")
    >>> @ENCODERS.register("none")
    ... class Identity: ...
    """

    def __init__(self, family: str):
        self.family = family
        self._entries: dict[str, Callable[..., Any]] = {}

    def register(self, name: str):
        def decorator(obj):
            if name in self._entries:
                raise ValueError(f"{self.family} '{name}' is registered twice")
            self._entries[name] = obj
            return obj

        return decorator

    def names(self) -> list[str]:
        return sorted(self._entries)

    def get(self, name: str) -> Callable[..., Any]:
        if name not in self._entries:
            raise KeyError(
                f"unknown {self.family} '{name}'; registered {self.family}s: {', '.join(self.names())}"
            )
        return self._entries[name]

    def build(self, cfg: Mapping[str, Any], **extra: Any) -> Any:
        """Build from a config mapping whose `name` picks the entry; the other keys are keyword arguments."""
        params = dict(cfg)
        name = params.pop("name", None)
        if name is None:
            raise KeyError(f"the {self.family} config has no 'name'; choose one of: {', '.join(self.names())}")
        return self.get(name)(**params, **extra)

    def __contains__(self, name: str) -> bool:
        return name in self._entries
