"""The worker's database step (service/cluster/work.py)."""

from __future__ import annotations

import pytest

from service.cluster.work import once_more_on_system_error


def test_a_spurious_system_error_is_retried_once() -> None:
    calls: list[int] = []

    def step() -> str:
        calls.append(1)
        if len(calls) == 1:
            raise SystemError("AST constructor recursion depth mismatch (before=81, after=43)")
        return "warm"

    assert once_more_on_system_error(step) == "warm" and len(calls) == 2


def test_a_second_system_error_and_other_errors_are_raised() -> None:
    def always() -> None:
        raise SystemError("again")

    with pytest.raises(SystemError):
        once_more_on_system_error(always)
    calls: list[int] = []

    def other() -> None:
        calls.append(1)
        raise ValueError("not transient")

    with pytest.raises(ValueError):
        once_more_on_system_error(other)
    assert len(calls) == 1
