"""The arm-process protocol (planners.arm_messages): every message survives the pipe between the
processes intact, names its job, and cannot be changed on the way."""
from __future__ import annotations

import dataclasses
import multiprocessing as mp

import numpy as np
import pytest

from humanoid_planner.core.planners.arm_messages import ArmMessage, Done, Found, Reachable, Ready, Solution, Stop


def messages() -> list:
    rng = np.random.default_rng(0)
    return [Ready(), Ready(3), Reachable(4, rng.normal(size=(5, 7)), np.arange(5)), Found(4, 2),
            Solution(4, rng.normal(size=(9, 7)), 2, cycles=120, tree_size=300),
            Done(4, cycles=130, tree_size=310, error=None, status=None),
            Done(5, cycles=0, tree_size=1, error="start in collision", status=4), Stop(4)]


def same(a, b) -> bool:
    """Field-by-field equality (arrays compared by value)."""
    return type(a) is type(b) and all(np.array_equal(getattr(a, f.name), getattr(b, f.name))
                                      if isinstance(getattr(a, f.name), np.ndarray) else
                                      getattr(a, f.name) == getattr(b, f.name) for f in dataclasses.fields(a))


def test_messages_cross_a_pipe_unchanged():
    here, there = mp.Pipe()
    sent = messages()
    for m in sent:
        here.send(m)
    got = [there.recv() for _ in sent]
    assert all(same(a, b) for a, b in zip(sent, got))
    assert [m.job_id for m in got] == [-1, 3, 4, 4, 4, 4, 5, 4]


def test_messages_are_frozen_and_typed():
    for m in messages():
        with pytest.raises(dataclasses.FrozenInstanceError):
            m.job_id = 99
    from_arm = [m for m in messages() if isinstance(m, ArmMessage)]
    assert len(from_arm) == len(messages()) - 1  # all but Stop, which goes the other way
    assert not isinstance(Stop(1), ArmMessage)
