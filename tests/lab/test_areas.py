"""Paper 004's windows (lab.areas): the training areas and the outages after them on a
synthetic path, and each window's figures against a hand computation."""
from __future__ import annotations

import math

import numpy as np
import pytest

from navtwin.lab import areas

#: Two boxes along the x axis: area 1 over x 0..10, area 2 over x 20..25.
BOXES = ((0.0, -1.0, 10.0, 1.0), (20.0, -1.0, 25.0, 1.0))


def _truth(t_end=40.0, speed=1.0):
    """Along y = 0 at *speed* m/s from x = 0, every millisecond."""
    t = np.arange(0.0, t_end + 5e-4, 0.001)
    return {"t": t, "x": speed * t, "y": np.zeros_like(t), "vx": np.full_like(t, speed),
            "vy": np.zeros_like(t)}


def test_each_sample_falls_in_its_area_or_the_outage_after_it():
    """x = 0..40 at 1 m: 0..10 area 1 (edges inside), 11..19 outage 1, 20..25 area 2, 26..40
    outage 2 (to the end); a point before the first area in none."""
    x = np.arange(-2.0, 41.0)
    w = areas.classify(BOXES, x, np.zeros_like(x))
    names = areas.window_names(2)
    assert names == ("area1", "outage1", "area2", "outage2")
    got = {n: x[w == i].tolist() for i, n in enumerate(names)}
    assert got == {"area1": list(np.arange(0.0, 11.0)), "outage1": list(np.arange(11.0, 20.0)),
                   "area2": list(np.arange(20.0, 26.0)), "outage2": list(np.arange(26.0, 41.0))}
    assert x[w == -1].tolist() == [-2.0, -1.0]


def test_an_area_never_reached_leaves_its_outage_to_the_end():
    x = np.arange(0.0, 15.0)
    w = areas.classify(((0.0, -1, 5.0, 1), (100.0, -1, 110.0, 1)), x, np.zeros_like(x))
    assert (w[:6] == 0).all() and (w[6:] == 1).all()


def test_window_figures_are_the_means_of_the_absolute_errors():
    """A track 1 s apart at t = 0..40 off by (+1, -2) m and (-0.5, +0.25) m/s in area 1, by a
    growing x error t - 10 m in outage 1 and so on: each mean computed by hand."""
    truth = _truth()
    t = np.arange(0.0, 41.0)
    dx = np.where(t <= 10, 1.0, t - 10.0)
    dy = np.where(t <= 10, -2.0, 0.0)
    dvx = np.where(t <= 10, -0.5, 0.1)
    dvy = np.where(t <= 10, 0.25, -0.2)
    e = {"t": t, "x": t + dx, "y": dy, "vx": 1.0 + dvx, "vy": dvy}
    got = areas.window_errors(BOXES, truth, {"hinf": e})["hinf"]
    assert list(got) == list(areas.columns(2))
    assert got["area1_n"] == 11 and got["area1_x_mean"] == pytest.approx(1.0)
    assert got["area1_y_mean"] == pytest.approx(2.0)
    assert got["area1_vx_mean"] == pytest.approx(0.5) and got["area1_vy_mean"] == pytest.approx(0.25)
    assert got["area1_mean"] == pytest.approx(math.sqrt(5.0))
    assert got["area1_duration_s"] == pytest.approx(10.0)
    # outage 1: t = 11..19, x error 1..9: mean 5; the window runs from x 10 to x 20
    assert got["outage1_n"] == 9 and got["outage1_x_mean"] == pytest.approx(5.0)
    assert got["outage1_mean"] == pytest.approx(5.0) and got["outage1_y_mean"] == 0.0
    assert got["outage1_vx_mean"] == pytest.approx(0.1) and got["outage1_vy_mean"] == pytest.approx(0.2)
    assert got["outage1_duration_s"] == pytest.approx(10.0)
    # area 2: t = 20..25, x error 10..15; outage 2: t = 26..40, x error 16..30, to the end
    assert got["area2_x_mean"] == pytest.approx(12.5) and got["area2_duration_s"] == pytest.approx(5.0)
    assert got["outage2_n"] == 15 and got["outage2_x_mean"] == pytest.approx(23.0)
    assert got["outage2_duration_s"] == pytest.approx(15.0)


def test_the_truths_velocity_is_interpolated_at_the_estimates_time_and_an_empty_window_is_nan():
    truth = _truth(t_end=12.0, speed=2.0)  # x 0..24: area 1 to t 5, outage 1, area 2 from t 10
    t = np.array([0.5, 2.5])
    e = {"t": t, "x": 2.0 * t, "y": np.zeros(2), "vx": np.array([2.5, 1.0]), "vy": np.zeros(2)}
    got = areas.window_errors(BOXES, truth, {"kf-rel": e})["kf-rel"]
    assert got["area1_vx_mean"] == pytest.approx(0.75) and got["area1_mean"] == pytest.approx(0.0)
    assert got["outage1_n"] == 0 and math.isnan(got["outage1_x_mean"])
    assert got["area2_duration_s"] == pytest.approx(2.0)


def test_the_boxes_are_the_scenarios_anchor_grids_in_order():
    class Grid:
        def __init__(self, box):
            self.box = box

    class Scenario:
        anchor_grids = (Grid(BOXES[0]), Grid(BOXES[1]))

    assert areas.boxes(Scenario()) == BOXES
