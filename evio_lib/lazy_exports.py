"""Names a package offers but imports on first use (PEP 562), so that importing the package stays cheap.

``python -m evio_lib COMMAND --help`` imports the package of the command's options (``evio_lib.features``,
``evio_lib.events``, ``evio_lib.pipeline``); an eager ``__init__`` would import OpenCV, torch and SciPy there first
(seconds). A package lists its names once::

    __getattr__, __dir__ = lazy_exports(__name__, {"create_detector": "base", ...}, globals())
    __all__ = [...]

>>> import types
>>> pkg = types.ModuleType("evio_lib.geometry")
>>> get, _ = lazy_exports("evio_lib.geometry", {"PinholeRadtan": "camera"}, vars(pkg))
>>> get("PinholeRadtan").__name__
'PinholeRadtan'
"""
from __future__ import annotations

import importlib
from typing import Any, Callable

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: dict[str, str], namespace: dict[str, Any]
                 ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """Return (``__getattr__``, ``__dir__``) for ``package``: ``exports`` maps a name to the submodule defining it.

    The first access imports ``package.submodule`` and stores the value in ``namespace`` (the package's globals),
    so later accesses are plain attribute lookups.
    """

    def __getattr__(name: str) -> Any:
        if name not in exports:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{exports[name]}"), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(exports))

    return __getattr__, __dir__
