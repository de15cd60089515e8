"""ros.processes.claim_domain_id: two runs on one machine never share a ROS domain (a listener
of one heard the other's node once, when both ran the node tests in the same domain)."""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap

import pytest

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.ros.processes import claim_domain_id, release_domain_id

FIRST, COUNT = 180, 3  # a range no other test module claims from (test_replay: 101-179)


def _other_process_claims(n: int) -> list[int]:
    """The domains another process gets when it claims n from the range while this one
    holds its own."""
    code = textwrap.dedent(f"""
        from cloth_mg_ros.ros.processes import claim_domain_id
        print([claim_domain_id({FIRST}, {COUNT}, {FIRST}) for _ in range({n})])
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=False)
    if out.returncode != 0:
        return [-1, out.stderr.strip().splitlines()[-1]]
    return ast.literal_eval(out.stdout)


def test_a_claimed_domain_is_not_given_to_another_process_until_released():
    mine = claim_domain_id(FIRST, COUNT, FIRST)
    assert mine == FIRST
    assert claim_domain_id(FIRST, COUNT, FIRST) == FIRST + 1  # this process skips its own
    assert _other_process_claims(1) == [FIRST + 2]
    result = _other_process_claims(2)  # the range holds one free id for it
    assert result[0] == -1 and "every ROS domain id in 180..182 is held" in result[1]
    release_domain_id(FIRST)
    release_domain_id(FIRST + 1)
    assert _other_process_claims(3) == [FIRST, FIRST + 1, FIRST + 2]  # its locks ended with it


def test_a_bad_range_is_named():
    with pytest.raises(ClothInputError, match="0..232"):
        claim_domain_id(230, 5, 233)
