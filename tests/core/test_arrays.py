"""unique_rows: the same answer as np.unique(axis=0), without numpy's structured view."""
import numpy as np
import pytest

from floodmesh.core.engine.arrays import unique_rows


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("dtype", [np.int64, np.float64])
def test_unique_rows_is_np_unique_axis_0(seed, dtype):
    rng = np.random.default_rng(seed)
    rows = rng.integers(-3, 4, (200, 1 + seed % 3)).astype(dtype)
    want, want_inverse = np.unique(rows, axis=0, return_inverse=True)
    got, inverse = unique_rows(rows, return_inverse=True)
    assert got.dtype == rows.dtype
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(inverse, want_inverse.ravel())
    np.testing.assert_array_equal(got[inverse], rows)


def test_unique_rows_of_nothing():
    got, inverse = unique_rows(np.empty((0, 2), np.int64), return_inverse=True)
    assert got.shape == (0, 2) and inverse.shape == (0,)


def test_ctrl_c_inside_unique_rows_stays_a_keyboard_interrupt():
    """numpy 2.2's np.unique(axis=0) turned about one such interrupt in eight into a TypeError
    (measured on Debian 13); unique_rows must pass every one through."""
    import signal

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    rows = np.random.default_rng(0).integers(0, 50, (50, 2))
    outcomes = []
    previous = signal.signal(signal.SIGALRM, interrupt)
    try:
        for i in range(400):
            # the timer set and cleared inside the handled block: an alarm that went off just
            # before the loop or while the timer was being cleared escaped the test (seen on a
            # loaded machine), where only one inside unique_rows is what is tested
            try:
                try:
                    signal.setitimer(signal.ITIMER_REAL, 0.0001 + (i % 97) * 0.00003)
                    for _ in range(2000):
                        unique_rows(rows, return_inverse=True)
                    outcomes.append("finished")
                finally:
                    signal.setitimer(signal.ITIMER_REAL, 0)
            except KeyboardInterrupt:
                outcomes.append("interrupted")
    finally:
        signal.signal(signal.SIGALRM, previous)
    assert set(outcomes) <= {"finished", "interrupted"} and "interrupted" in outcomes


def test_without_huge_pages_turns_numpys_request_off_and_back():
    """Inside the block numpy asks for no transparent huge pages (the gridding's page faults
    stalled on compaction); on leaving, even by an exception, the setting is what it was."""
    from floodmesh.core.engine.arrays import huge_page_switch, without_huge_pages

    switch = huge_page_switch()
    if switch is None:
        pytest.skip("this numpy has no huge-page switch")
    initial = switch(True)
    for setting in (True, False):
        switch(setting)
        with pytest.raises(KeyError), without_huge_pages():
            assert switch(False) is False  # off inside (asking returns the setting)
            raise KeyError
        assert switch(initial) is setting
