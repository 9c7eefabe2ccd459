"""Demonstration CSV loader: valid files load, each kind of bad file fails with file:line."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.errors import UserInputError
from distgprl.skill.demos import load_demonstration, save_demonstration

HEADER = "t,x,y,z,rx,ry,rz\n"


def write(tmp_path, text, name="demo.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_round_trip(tmp_path, smooth_demo):
    path = tmp_path / "d.csv"
    save_demonstration(path, smooth_demo.times, smooth_demo.poses)
    demo = load_demonstration(path)
    np.testing.assert_allclose(demo.poses, smooth_demo.poses, atol=1e-6)
    assert len(demo.sha256) == 64 and demo.name == "d"


def test_column_order_may_differ(tmp_path):
    path = write(tmp_path, "x,y,z,rx,ry,rz,t\n1,2,3,4,5,6,0\n1,2,3,4,5,6,1\n")
    demo = load_demonstration(path)
    np.testing.assert_array_equal(demo.times, [0, 1])
    np.testing.assert_array_equal(demo.poses[0], [1, 2, 3, 4, 5, 6])


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("t,x,y,z,rx,ry\n0,1,2,3,4,5\n1,1,2,3,4,5\n", r":1: missing column\(s\) rz"),
        (HEADER + "0,1,2,3,4,5,6\n1,1,abc,3,4,5,6\n", r":3: column 'y' is not a number"),
        (HEADER + "0,1,2,3,4,5,6\n1,1,2,nan,4,5,6\n", r":3: column 'z' is not finite"),
        (HEADER + "0,1,2,3,4,5,6\n1,1,2,inf,4,5,6\n", r":3: column 'z' is not finite"),
        (HEADER + "0,1,2,3,4,5,6\n0,1,2,3,4,5,6\n", r":3: time 0 is not greater"),
        (HEADER + "0,1,2,3,4,5,6\n1,1,2,3,4,5\n", r":3: expected 7 cells, found 6"),
        (HEADER + "0,1,2,3,4,5,6\n", r"1 data row\(s\), need at least 2"),
        ("", r":1: empty file"),
        ("t,x,y,z,rx,ry,rz,extra\n", r"unexpected column\(s\) extra"),
    ],
)
def test_bad_files_name_file_line_and_problem(tmp_path, text, expected):
    path = write(tmp_path, text)
    with pytest.raises(UserInputError, match=expected) as info:
        load_demonstration(path)
    assert str(path) in str(info.value)
    assert "\n" not in str(info.value)


def test_fewer_rows_than_required(tmp_path):
    path = write(tmp_path, HEADER + "".join(f"{i},0,0,0,0,0,0\n" for i in range(5)))
    with pytest.raises(UserInputError, match="5 data row"):
        load_demonstration(path, min_rows=15)


def test_missing_file(tmp_path):
    with pytest.raises(UserInputError, match="cannot read"):
        load_demonstration(tmp_path / "nope.csv")
