"""The dwell-point lattice and the two visiting orders: every point with dwell visited, only by neighbouring moves."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from fuzz import fuzz_settings
from wavestack.pipeline.polishing.path import PointLattice, raster_order, spiral_order

masks = st.tuples(st.integers(1, 16), st.integers(1, 16)).flatmap(lambda shape: hnp.arrays(bool, shape))


@fuzz_settings(200)
@given(h=st.integers(1, 40), w=st.integers(1, 40), step_px=st.integers(1, 6), data=st.data())
def test_the_lattice_keeps_the_total_and_stays_on_the_grid(h: int, w: int, step_px: int, data: st.DataObject) -> None:
    lattice = PointLattice((h, w), step_px)
    values = data.draw(hnp.arrays(np.float64, (h, w), elements=st.floats(0.0, 10.0)))
    sums = lattice.block_sum(values)
    assert sums.shape == (-(-h // step_px), -(-w // step_px))
    assert sums.sum() == np.float64(values.sum()) or np.isclose(sums.sum(), values.sum(), rtol=1e-12)
    rows, cols = lattice.point_px(np.arange(sums.shape[0]), np.arange(sums.shape[1]))
    assert rows.min() >= 0 and rows.max() <= h - 1 and cols.min() >= 0 and cols.max() <= w - 1
    # centred: as much grid left before the first point as after the last
    assert np.isclose(rows[0], (h - 1) - rows[-1]) and np.isclose(cols[0], (w - 1) - cols[-1])


def test_each_pixel_goes_to_its_nearest_point() -> None:
    # 7 pixels at step 3: points at pixels 0, 3, 6; pixel 1 -> 0, pixel 2 -> 3, pixel 5 -> 6
    lattice = PointLattice((1, 7), 3)
    one_hot = np.zeros((1, 7))
    one_hot[0, 2] = 1.0
    assert lattice.block_sum(one_hot).tolist() == [[0.0, 1.0, 0.0]]
    one_hot[0, 2], one_hot[0, 1] = 0.0, 1.0
    assert lattice.block_sum(one_hot).tolist() == [[1.0, 0.0, 0.0]]


def _visits(order: tuple[np.ndarray, np.ndarray]) -> list[tuple[int, int]]:
    return list(zip(order[0].tolist(), order[1].tolist()))


@fuzz_settings(200)
@given(mask=masks)
def test_the_raster_visits_every_point_with_dwell_once_by_single_steps(mask: np.ndarray) -> None:
    i, j = raster_order(mask)
    visits = _visits((i, j))
    assert len(visits) == len(set(visits))
    assert {(int(a), int(b)) for a, b in zip(*np.nonzero(mask))} <= set(visits)
    if len(visits) > 1:
        moves = np.abs(np.diff(i)) + np.abs(np.diff(j))
        assert np.all(moves == 1)  # along the row, or one row down at a turn
        assert np.all(np.diff(i) >= 0)  # rows top to bottom


@fuzz_settings(200)
@given(mask=masks)
def test_the_spiral_visits_every_point_with_dwell_by_neighbouring_moves(mask: np.ndarray) -> None:
    i, j = spiral_order(mask)
    visits = _visits((i, j))
    assert {(int(a), int(b)) for a, b in zip(*np.nonzero(mask))} <= set(visits)
    assert np.all((i >= 0) & (i < mask.shape[0]) & (j >= 0) & (j < mask.shape[1]))
    if len(visits) > 1:
        assert np.all(np.maximum(np.abs(np.diff(i)), np.abs(np.diff(j))) == 1)


def test_the_spiral_winds_outwards_from_the_centre() -> None:
    yy, xx = np.indices((21, 21))
    disc = (yy - 10) ** 2 + (xx - 10) ** 2 <= 81
    i, j = spiral_order(disc)
    assert (int(i[0]), int(j[0])) == (10, 10)
    radius = np.hypot(i - 10, j - 10)
    # each quarter of the visits lies farther out than the one before, on average
    quarters = np.array_split(radius, 4)
    means = [q.mean() for q in quarters]
    assert means == sorted(means)
    # a filled disc needs few bridges: under 10 % extra visits
    assert len(i) <= 1.1 * disc.sum()


def test_empty_masks_give_empty_orders() -> None:
    for order in (raster_order, spiral_order):
        i, j = order(np.zeros((3, 4), dtype=bool))
        assert i.size == 0 and j.size == 0
