"""The shared config checks: one-line InputErrors naming the key and what was expected."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from autonomy.common.errors import InputError, require_int, require_non_negative, require_positive


@dataclass
class C:
    a: object = 1.0
    n: object = 3


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), "1", None, True])
def test_require_positive(bad) -> None:
    require_positive(C(), "x.", "a", "n")
    with pytest.raises(InputError, match=r"^x\.a: expected a positive number, got "):
        require_positive(C(a=bad), "x.", "a")


@pytest.mark.parametrize("bad", [-0.5, float("nan"), "0", True])
def test_require_non_negative(bad) -> None:
    require_non_negative(C(a=0), "", "a")
    with pytest.raises(InputError, match=r"^a: expected a number >= 0, got "):
        require_non_negative(C(a=bad), "", "a")


@pytest.mark.parametrize("bad", [0, 2.0, "3", True])
def test_require_int(bad) -> None:
    require_int(C(n=1), "y.", "n")
    require_int(C(n=0), "y.", "n", minimum=0)
    with pytest.raises(InputError, match=r"^y\.n: expected an integer >= 1, got "):
        require_int(C(n=bad), "y.", "n")
