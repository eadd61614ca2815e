"""append_rows: the per-node arrays of a tissue grow without copying the model at every cut step."""

import numpy as np

from cutkit.relax.growable import append_rows


def test_appending_one_row_at_a_time_equals_concatenation_and_copies_rarely():
    a = np.arange(6.0).reshape(2, 3)
    want = a.copy()
    buffers = set()
    for k in range(1000):
        row = np.full((1, 3), float(k))
        a = append_rows(a, row)
        want = np.concatenate([want, row])
        buffers.add(id(a.base))
    np.testing.assert_array_equal(a, want)
    assert len(buffers) <= 10  # doubling: about log2(1000) buffers, not 1000 copies


def test_a_view_of_someone_elses_buffer_is_copied_not_written_through():
    X = np.zeros((100, 3))
    a = X[:10]
    b = append_rows(a, np.ones((2, 3)))
    assert b.shape == (12, 3) and np.all(b[10:] == 1.0)
    assert np.all(X == 0.0)  # rows 10 and 11 of the foreign buffer untouched
    c = append_rows(X[:0], np.ones((1, 3)))
    assert c.shape == (1, 3) and np.all(X == 0.0)


def test_rows_are_cast_and_shaped_and_the_input_keeps_its_length():
    flags = np.zeros((3, 3), bool)
    grown = append_rows(flags, [True, False, True])  # one row, cast to bool
    assert grown.dtype == bool and grown.shape == (4, 3)
    np.testing.assert_array_equal(grown[3], [True, False, True])
    assert flags.shape == (3, 3)
    ids = append_rows(np.zeros(0, np.int32), np.array([2.0, 5.0]))
    assert ids.dtype == np.int32 and ids.tolist() == [2, 5]


def test_an_older_view_is_copied_so_rows_appended_since_stay():
    a = append_rows(np.zeros((0, 2)), np.ones((3, 2)))
    b = append_rows(a, np.full((1, 2), 2.0))  # in place: b shares a's buffer
    assert b.base is a.base
    c = append_rows(a, np.full((1, 2), 7.0))  # a is no longer the newest view: copied
    assert c.base is not a.base
    np.testing.assert_array_equal(b[3], [2.0, 2.0])
    np.testing.assert_array_equal(c[3], [7.0, 7.0])
