import pytest

from companion.tracking import CentroidFilter, KalmanCentroidFilter, TrackingConfig


def test_first_frame_without_centroid_is_none():
    f = CentroidFilter()
    assert f.update(None) is None
    assert f.used is None


def test_first_centroid_is_accepted():
    f = CentroidFilter()
    assert f.update((10.0, 20.0)) == (10.0, 20.0)
    assert f.last_accepted


def test_within_tau_is_accepted_inclusive():
    f = CentroidFilter(TrackingConfig(tau_c_px=80.0))
    f.update((100.0, 100.0))
    assert f.update((148.0, 164.0)) == (148.0, 164.0)     # distance exactly 80
    assert f.last_accepted


def test_beyond_tau_reuses_last_used():
    f = CentroidFilter()
    f.update((100.0, 100.0))
    assert f.update((181.0, 100.0)) == (100.0, 100.0)     # 81 px jump rejected
    assert not f.last_accepted
    # the comparison is against the last *used* centroid, not the rejected measurement
    assert f.update((170.0, 100.0)) == (170.0, 100.0)


def test_none_with_history_reuses_last_used():
    f = CentroidFilter()
    f.update((50.0, 60.0))
    assert f.update(None) == (50.0, 60.0)
    assert f.update(None) == (50.0, 60.0)
    assert not f.last_accepted


def test_reset_forgets():
    f = CentroidFilter()
    f.update((50.0, 60.0))
    f.reset()
    assert f.update(None) is None


def test_kalman_follows_rule_and_smooths():
    k = KalmanCentroidFilter()
    assert k.update(None) is None
    assert k.update((100.0, 100.0)) == (100.0, 100.0)
    out = k.update((104.0, 100.0))
    assert 100.0 < out[0] <= 104.0 and k.last_accepted
    far = k.update((300.0, 100.0))                        # gated out: prediction kept
    assert not k.last_accepted and far[0] < 120.0
    assert k.update(None) is not None


@pytest.mark.parametrize("bad", [(float("nan"), 1.0)])
def test_non_finite_measurement_is_treated_as_none(bad):
    f = CentroidFilter()
    f.update((1.0, 1.0))
    assert f.update(bad) == (1.0, 1.0)
