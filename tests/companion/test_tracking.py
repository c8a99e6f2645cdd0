import numpy as np
import pytest

from companion.tracking import (
    CentroidFilter,
    ConfirmingCentroidFilter,
    KalmanCentroidFilter,
    KalmanConfig,
    TrackingConfig,
)


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


# --- edges: the flags are booleans, non-finite measurements in either coordinate, the Kalman filter's maths ---

NON_FINITE = [(float("nan"), 1.0), (1.0, float("nan")), (float("inf"), 2.0), (2.0, float("-inf"))]


@pytest.mark.parametrize("bad", NON_FINITE)
@pytest.mark.parametrize("make", [CentroidFilter, ConfirmingCentroidFilter, KalmanCentroidFilter])
def test_a_non_finite_first_measurement_is_no_measurement(make, bad):
    f = make()
    assert f.used is None and f.last_accepted is False
    assert f.update(bad) is None and f.used is None and f.last_accepted is False


@pytest.mark.parametrize("bad", NON_FINITE)
def test_a_non_finite_measurement_keeps_the_confirmed_centroid(bad):
    f = ConfirmingCentroidFilter()
    f.update((10.0, 10.0))
    f.update((12.0, 11.0))
    assert f.update(bad) == (12.0, 11.0) and f.last_accepted is False


def test_flags_are_false_after_reset_and_on_rejection():
    for f in (CentroidFilter(), ConfirmingCentroidFilter(), KalmanCentroidFilter()):
        f.update((10.0, 10.0))
        f.update((10.0, 12.0))
        f.reset()
        assert f.used is None and f.last_accepted is False
    f = CentroidFilter()
    f.update((10.0, 10.0))
    assert f.update(None) == (10.0, 10.0) and f.last_accepted is False


def test_confirming_filter_edges():
    tau = TrackingConfig().tau_c_px
    f = ConfirmingCentroidFilter(reacquire_after=3)
    f.update((100.0, 100.0))
    assert f.update((100.0, 100.0 + tau)) == (100.0, 100.0 + tau) and f.last_accepted is True   # exactly τ
    # far candidates: exactly τ apart still agree; three are needed to replace a used centroid
    assert f.update((300.0, 100.0)) == (100.0, 100.0 + tau) and f.last_accepted is False
    assert f.update((300.0 + tau, 100.0)) == (100.0, 100.0 + tau)
    assert f.update((300.0 + tau, 100.0 + 1.0)) == (300.0 + tau, 101.0) and f.last_accepted is True
    # seeded: used at once, the seed's coordinates in order
    g = ConfirmingCentroidFilter()
    g.seed((7, 9))
    assert g.used == (7.0, 9.0)
    assert g.update((7.0, 9.0 + tau)) == (7.0, 9.0 + tau)     # within τ of the seed: accepted
    g.seed((50.0, 60.0))
    g.update((400.0, 300.0))
    assert g.update((401.0, 300.0)) == (401.0, 300.0)          # candidates cleared by the seed: two agree
    g.reset()
    assert g.update((5.0, 5.0)) is None                        # nothing used: a first centroid needs a second


def reference_kalman(measurements, cfg):
    """Textbook constant-velocity Kalman filter on [u, u', v, v'] with τ gating against the prediction;
    Q of a white-acceleration (piecewise constant) model: var·[[dt⁴/4, dt³/2], [dt³/2, dt²]] per axis."""
    dt, s2, v2 = cfg.dt, cfg.measurement_std_px ** 2, cfg.initial_velocity_std_px ** 2
    f1 = np.array([[1.0, dt], [0.0, 1.0]])
    F = np.kron(np.eye(2), f1)
    H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    q1 = cfg.accel_std_px ** 2 * np.array([[dt ** 4 / 4, dt ** 3 / 2], [dt ** 3 / 2, dt ** 2]])
    Q = np.kron(np.eye(2), q1)
    R = np.eye(2) * s2
    x = P = None
    out = []
    for z in measurements:
        if x is None:
            x, P = np.array([z[0], 0.0, z[1], 0.0]), np.diag([s2, v2, s2, v2])
        else:
            x, P = F @ x, F @ P @ F.T + Q
            if np.hypot(z[0] - x[0], z[1] - x[2]) <= cfg.tau_c_px:
                S = H @ P @ H.T + R
                K = P @ H.T @ np.linalg.inv(S)
                x = x + K @ (np.asarray(z) - H @ x)
                P = (np.eye(4) - K @ H) @ P
        out.append((x[0], x[2]))
    return out


@pytest.mark.parametrize("cfg", [KalmanConfig(), KalmanConfig(dt=0.5, measurement_std_px=2.5, accel_std_px=5.0,
                                                                initial_velocity_std_px=12.0)])
def test_kalman_filter_matches_the_textbook_filter(cfg):
    rng = np.random.default_rng(3)
    k = np.arange(25)
    track = np.stack([100 + 6.0 * k, 80 - 3.0 * k + 0.2 * k ** 2], 1) + rng.normal(0, 3, (25, 2))
    track[12] = (600.0, 20.0)                                  # a jump, gated out
    want = reference_kalman([tuple(z) for z in track], cfg)
    f = KalmanCentroidFilter(cfg)
    for z, w in zip(track, want, strict=True):
        assert f.update((float(z[0]), float(z[1]))) == pytest.approx(w, abs=1e-9)
    # gating is inclusive at exactly τ from the prediction (a filter at rest predicts where it is)
    g = KalmanCentroidFilter(cfg)
    g.update((100.0, 100.0))
    g.update((100.0, 100.0 + cfg.tau_c_px))
    assert g.last_accepted is True


@pytest.mark.parametrize("bad", NON_FINITE)
def test_a_non_finite_measurement_is_never_a_candidate(bad):
    f = ConfirmingCentroidFilter()
    f.update(bad)
    assert f.update((10.0, 10.0)) is None                      # the first real one still needs confirming
    assert f.update((11.0, 10.0)) == (11.0, 10.0) and f.last_accepted is True


def test_flags_on_acceptance_and_rejection_and_a_reset_kalman_starts_over():
    f = CentroidFilter()
    f.update((10.0, 10.0))
    assert f.update((200.0, 10.0)) == (10.0, 10.0) and f.last_accepted is False
    g = ConfirmingCentroidFilter()
    g.update((10.0, 10.0))
    g.update((12.0, 10.0))
    assert g.update((14.0, 10.0)) == (14.0, 10.0) and g.last_accepted is True    # within τ of the used one
    k = KalmanCentroidFilter()
    assert k.update((10.0, 10.0)) == (10.0, 10.0) and k.last_accepted is True
    k.update((12.0, 10.0))
    k.reset()
    assert k.update(None) is None and k.used is None
    assert k.update((50.0, 60.0)) == (50.0, 60.0)              # a fresh start at the new measurement
