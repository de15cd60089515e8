"""Which optional install ("extra") brings a module that a command needs.

`pip install cloth_mg_ros` installs what the node and the headless runs need; the benchmarks'
charts and baselines come with ``[bench]``, the Dask cluster with ``[cluster]`` (setup.py).
A command that reaches for a module of an extra that is not installed says which one.
"""

from __future__ import annotations

import importlib.util

from cloth_mg_ros.errors import ClothInputError

__all__ = ["EXTRAS", "EXTRA_MODULES", "extra_of", "missing_extra_message", "require_extra",
           "require_extras"]

# each extra's modules (setup.py's extras_require, by import name)
EXTRA_MODULES = {"bench": ("distributed", "matplotlib", "PIL", "pyamg", "threadpoolctl"),
                 "cluster": ("distributed",)}
# top-level module -> the smallest extra that installs it (mpl_toolkits comes with
# matplotlib, dask with distributed)
EXTRAS = {"matplotlib": "bench", "mpl_toolkits": "bench", "PIL": "bench", "pyamg": "bench",
          "threadpoolctl": "bench", "distributed": "cluster", "dask": "cluster"}


def extra_of(module: str | None) -> str | None:
    """The extra whose install brings `module` (a dotted name), or None for any other."""
    return EXTRAS.get((module or "").split(".")[0])


def _needs(what: str, modules: list[str], extra: str) -> str:
    """'`what` needs a, b and c, which the 'extra' extra installs: pip install ...'."""
    names = " and ".join([", ".join(modules[:-1]), modules[-1]] if len(modules) > 1
                         else modules)
    return (f"{what} needs {names}, which the '{extra}' extra installs: "
            f"pip install 'cloth_mg_ros[{extra}]'")


def missing_extra_message(module: str, what: str) -> str:
    """`what` needs `module`, and the pip command that installs its extra."""
    return _needs(what, [module.split(".")[0]], extra_of(module))


def _importable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ImportError:  # a finder that refuses it
        return False


def require_extra(module: str, what: str) -> None:
    """ClothInputError naming the extra to install unless `module` can be imported."""
    if not _importable(module):
        raise ClothInputError(missing_extra_message(module, what))


def require_extras(extra: str, what: str) -> None:
    """ClothInputError naming every module of the extra `extra` that cannot be imported, and
    the extra, unless all can."""
    missing = [m for m in EXTRA_MODULES[extra] if not _importable(m)]
    if missing:
        raise ClothInputError(_needs(what, missing, extra))
