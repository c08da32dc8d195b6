"""Fixtures shared by the tests: the helpers of ``tests/helpers.py``, the command line
bound to pytest's captured output."""

import pytest

import helpers


@pytest.fixture
def block_scene():
    """The factory :func:`helpers.block_scene` (a block in a 4 x 3 grid)."""
    return helpers.block_scene


@pytest.fixture
def run_cli(capsys):
    """``run_cli(argv) -> (exit code, stdout, stderr)`` of ``femgrid-mpm ARGV`` in process."""
    return lambda argv: helpers.run_cli(argv, capsys)
