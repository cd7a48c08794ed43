"""The registry of backends: the only place that names them.

:data:`BACKENDS` maps each name a run config may give in ``backend:`` to the module that
implements it; that module defines ``BACKEND``, its
:class:`~mmexec.drivers.backendspec.BackendSpec` (section parser, capabilities, builder,
run options it honours, fault patches...). A module is imported only when a config names
its backend, so importing this registry imports neither pybullet nor a device package.
Adding a backend is one module with a ``BACKEND`` spec plus one line here
(docs/architecture.md, "How to add a backend").
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator
from typing import Any

from mmexec.config.yamlload import InputError, Mark
from mmexec.drivers.backendspec import BackendSpec

__all__ = ["BACKENDS", "SPEC_ATTRIBUTE", "backend_spec", "names", "specs"]

#: backend name -> module path of its implementation (the module's ``BACKEND`` spec).
BACKENDS: dict[str, str] = {
    "mock": "mmexec.drivers.mock.backend",
    "sim": "mmexec.sim.backend",
    "robot": "mmexec.drivers.robot",
}

#: The module-level name each backend module gives its spec.
SPEC_ATTRIBUTE = "BACKEND"


def names() -> tuple[str, ...]:
    """The registered backend names, in registry order."""
    return tuple(BACKENDS)


def backend_spec(name: str, mark: Mark) -> BackendSpec[Any]:
    """The spec of backend ``name``; InputError (at ``mark``) when the backend is unknown
    or its module is not part of this installation or cannot load."""
    module_name = BACKENDS.get(name)
    if module_name is None:
        raise InputError.at(mark, f"backend: unknown backend {name!r} (expected one of: {', '.join(BACKENDS)})")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        if e.name and (module_name == e.name or module_name.startswith(e.name + ".")):
            raise InputError.at(
                mark, f"backend: {name!r} is not available in this installation (module {module_name} not found)"
            ) from None
        raise InputError.at(
            mark, f"backend: {name!r} cannot load: {module_name} needs {e.name!r}, which is not installed"
        ) from None
    spec = getattr(module, SPEC_ATTRIBUTE, None)
    if not isinstance(spec, BackendSpec):
        raise InputError.at(mark, f"backend: {name!r} is not available: {module_name} has no {SPEC_ATTRIBUTE} spec")
    if spec.name != name:
        raise InputError.at(mark, f"backend: {name!r} is not available: {module_name} describes backend "
                                  f"{spec.name!r}")
    return spec


def specs(mark: Mark) -> Iterator[BackendSpec[Any]]:
    """The spec of every registered backend, in registry order (each module imported);
    InputError at ``mark`` as :func:`backend_spec`."""
    for name in BACKENDS:
        yield backend_spec(name, mark)
