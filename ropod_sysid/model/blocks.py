"""Where each group's blocks go in the platform's arrays: a group's rows (its base rows, then
its own coordinates') and its channels placed at their indices, taken back out, and the index
forms that write in place. Small pure functions; :mod:`ropod_sysid.model.assembly` sums the
groups' contributions with them."""

from __future__ import annotations

import numpy as np


def whole(idx: np.ndarray, size: int) -> bool:
    """Are the indices ``idx`` 0, 1, …, size − 1 (a group that is the whole platform)? (A
    byte comparison: the check runs several times per evaluation of the dynamics.)"""
    return idx.size == size and idx.tobytes() == np.arange(size, dtype=idx.dtype).tobytes()


def gather(parts: list[tuple[np.ndarray, np.ndarray]], size: int, axis: int) -> np.ndarray:
    """Per-group arrays (indices, values) placed at their indices along ``axis``."""
    if len(parts) == 1 and whole(parts[0][0], size):
        return parts[0][1]
    shape = list(parts[0][1].shape)
    shape[axis] = size
    out = np.empty(shape)
    for idx, values in parts:
        sl = [slice(None)] * len(shape)
        sl[axis] = idx  # type: ignore[call-overload]
        out[tuple(sl)] = values
    return out


def placed(values: np.ndarray, idx: np.ndarray, size: int, axes: tuple[int, ...] = (1,)
          ) -> np.ndarray:
    """A group's rows (its base rows, then its own coordinates') placed at ``idx`` of ``size``
    along each of ``axes``; zeros elsewhere."""
    if values.shape[axes[0]] == size and whole(idx, size):
        return values
    shape = list(values.shape)
    for ax in axes:
        shape[ax] = size
    out = np.zeros(shape)
    sl: list[object] = [slice(None)] * len(shape)
    if len(axes) == 1:
        sl[axes[0]] = idx
        out[tuple(sl)] = values  # type: ignore[index]
    else:
        out[:, idx[:, None], idx[None, :]] = values
    return out


def take(values: np.ndarray, idx: np.ndarray, axis: int) -> np.ndarray:
    """``values`` at ``idx`` along ``axis``; the array itself when ``idx`` covers it all."""
    values = np.asarray(values, float)
    if whole(idx, values.shape[axis]):
        return values
    return np.take(values, idx, axis=axis)


def cells(rows: np.ndarray, cols: np.ndarray | slice) -> tuple[np.ndarray, ...] | tuple:
    """Index of the block rows × cols of an (N, D, p) array (after its sample axis)."""
    if isinstance(cols, slice):
        return rows, cols
    return rows[:, None], cols[None, :]


def spot(idx: list[int]) -> np.ndarray | slice:
    """Column indices as a slice when they are consecutive (writes in place), else an array."""
    if idx and idx == list(range(idx[0], idx[0] + len(idx))):
        return slice(idx[0], idx[0] + len(idx))
    return np.array(idx, int)
