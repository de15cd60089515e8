"""Read-only arrays that stay read-only through copies and pickles.

Tables that never change once built (the mesh's `MeshLevel` and `LevelTransfer`, the
self-contact's rest shape and the pairs it finds) are read-only. numba types a read-only
array apart from a writable one and compiles (and caches) each kernel once per kind, so
every path hands a kernel the same kind. numpy's deepcopy and unpickling give writable
arrays back: a copied garment (the benches run copies of one settled garment) compiled some
twenty kernels again, about 30 s on 2 cores, in a process whose kernels `cloth-mg warmup`
had all cached.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

__all__ = ['FrozenArrays', 'frozen']


def frozen(a: np.ndarray) -> np.ndarray:
    """Make an array read-only (in place) and return it."""
    a.setflags(write=False)
    return a


def _read_only(value: Any) -> bool:
    return isinstance(value, np.ndarray) and not value.flags.writeable


class FrozenArrays:
    """Mixin: a deepcopy shares the read-only array attributes (nothing can write them) and
    copies the rest; a pickle restores them read-only."""

    def __deepcopy__(self, memo: dict) -> Any:
        new = object.__new__(type(self))
        memo[id(self)] = new
        for name, value in vars(self).items():
            setattr(new, name, value if _read_only(value) else copy.deepcopy(value, memo))
        return new

    def __getstate__(self) -> tuple[dict, tuple[str, ...]]:
        state = dict(vars(self))
        return state, tuple(k for k, v in state.items() if _read_only(v))

    def __setstate__(self, state: tuple[dict, tuple[str, ...]]) -> None:
        values, read_only = state
        vars(self).update(values)
        for name in read_only:
            frozen(getattr(self, name))
