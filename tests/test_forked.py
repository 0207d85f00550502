"""Work split by rows over forked processes (:mod:`ropod_sysid.forked`)."""

from __future__ import annotations

import multiprocessing
import os

import numpy as np
import pytest

from ropod_sysid.forked import PROCESSES_ENV, ForkedMap, default_processes


def _square_and_pid(x: np.ndarray) -> np.ndarray:
    if (x < 0).any():
        raise ValueError(f"negative row in a share of {len(x)}")
    return np.column_stack([x[:, 0] ** 2, np.full(len(x), os.getpid())])


def test_a_split_gives_the_values_in_order_from_two_processes():
    x = np.arange(7.0)[:, None]
    with ForkedMap(_square_and_pid, 2) as split:
        assert split.processes == 2
        out = split(x)
        again = split(x[:1])  # one row: this process alone
    np.testing.assert_array_equal(out[:, 0], x[:, 0] ** 2)
    pids = out[:, 1].astype(int)
    assert pids[0] == os.getpid() and len(set(pids)) == 2  # shares of 3 and 4 rows
    assert list(pids).count(os.getpid()) == 3
    assert again[0, 1] == os.getpid()
    assert not [p for p in multiprocessing.active_children() if p.name == "ropod-sysid-helper"]


def _batch_sums(x: np.ndarray) -> np.ndarray:
    """Each row's value with its share's length (the batch it was evaluated in)."""
    return np.column_stack([x[:, 0], np.full(len(x), len(x))])


def test_shares_keep_the_pieces_whole():
    x = np.arange(10.0)[:, None]
    with ForkedMap(_batch_sums, 2) as split:
        out = split(x, [4, 3, 3])  # shares of pieces: [4] and [3, 3]
        assert list(out[:, 1]) == [4] * 4 + [6] * 6
        assert list(split(x)[:, 1]) == [5] * 10  # single rows: halves
        with pytest.raises(ValueError, match=r"pieces \[4, 3\] do not make up 10 rows"):
            split(x, [4, 3])
    np.testing.assert_array_equal(out[:, 0], x[:, 0])


def test_a_helpers_error_is_raised_here_and_the_helpers_end():
    x = np.array([[1.0], [2.0], [-3.0], [4.0]])  # the negative row is in the helper's share
    split = ForkedMap(_square_and_pid, 2)
    with pytest.raises(ValueError, match="negative row in a share of 2"):
        split(x)
    np.testing.assert_array_equal(split(np.abs(x))[:, 0], [1.0, 4.0, 9.0, 16.0])  # still serves
    split.close()
    assert not [p for p in multiprocessing.active_children() if p.name == "ropod-sysid-helper"]
    with pytest.raises(ValueError, match="at least 1"):
        ForkedMap(_square_and_pid, 0)


def test_the_processes_follow_the_environment(monkeypatch):
    monkeypatch.setenv(PROCESSES_ENV, "1")
    assert default_processes() == 1
    monkeypatch.setenv(PROCESSES_ENV, "3")
    assert default_processes() == 3
    monkeypatch.setenv(PROCESSES_ENV, "many")
    assert default_processes() == (2 if len(os.sched_getaffinity(0)) > 1 else 1)
