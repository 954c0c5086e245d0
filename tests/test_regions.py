import numpy as np
import pytest

from parcelfit.runs import Box, Polygon, Trajectory, crop, parse_region, region_mask


def test_box_with_margin_and_open_axis():
    box = parse_region({"x": [0.0, 1.0]})
    assert box == Box(xmin=0.0, xmax=1.0)
    pts = np.array([[-0.05, 10.0], [-0.01, 0.0], [0.5, -3.0], [1.02, 0.0]])
    assert box.contains(pts).tolist() == [False, False, True, False]
    assert box.contains(pts, margin=0.02).tolist() == [False, True, True, True]


def test_polygon_margin_is_distance_to_edges():
    tri = Polygon(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]))
    # (0.6, 0.6) lies 0.2/sqrt(2) = 0.1414 m beyond the hypotenuse; (-0.1, -0.1) 0.1414 m from the corner
    pts = np.array([[0.2, 0.2], [0.6, 0.6], [-0.1, -0.1], [2.0, 2.0]])
    assert tri.contains(pts).tolist() == [True, False, False, False]
    assert tri.contains(pts, margin=0.14).tolist() == [True, False, False, False]
    assert tri.contains(pts, margin=0.142).tolist() == [True, True, True, False]


def test_crop_keeps_samples_in_any_region():
    t = np.arange(11) * 0.1
    tr = Trajectory(t=t, x=t, y=np.zeros(11), theta=np.zeros(11))
    regions = (Box(xmin=0.0, xmax=0.25), Box(xmin=0.75, xmax=0.9))
    mask = region_mask(tr, regions)
    assert np.flatnonzero(mask).tolist() == [0, 1, 2, 8, 9]
    assert len(crop(tr, regions, margin=0.06)) == 7
    assert crop(tr, ()) is tr
    with pytest.raises(ValueError, match=">= 0"):
        region_mask(tr, regions, margin=-1)
