"""Optional dependencies: each lives in an extra of the package, and a missing one is a
one-line error that names the extra to install."""

from __future__ import annotations

from importlib import import_module
from types import ModuleType

from mocodec.errors import MocodecError


def require(module: str, extra: str, what: str) -> ModuleType:
    """``module`` imported, or MocodecError: ``what`` needs it, from ``mocodec[extra]``."""
    try:
        return import_module(module)
    except ImportError:
        raise MocodecError(f"{what} needs {module.split('.')[0]}: pip install 'mocodec[{extra}]'") from None
