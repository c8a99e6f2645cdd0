"""Sensors + estimator: exact truth without noise, convergence with noise, seeded determinism."""

import math

import numpy as np
import pytest

from sitl_vehicle.control.qmath import qconj, qmul
from sitl_vehicle.estimator import Estimator
from sitl_vehicle.sensors import Imu, PoseSensor, SensorNoise
from sitl_vehicle.sim import Setpoint, VehicleConfig, VehicleSim


def att_error_deg(q1, q2):
    e = qmul(qconj(q1), q2)
    return math.degrees(2.0 * math.asin(min(1.0, math.sqrt(e[1] ** 2 + e[2] ** 2 + e[3] ** 2))))


def test_no_noise_estimate_is_exact_truth():
    sim = VehicleSim(VehicleConfig(noise=None))
    sim.set_armed(True)
    sim.set_setpoint(Setpoint(position=(1.0, -1.0, -1.0), yaw=0.5))
    for _ in range(6):
        sim.run(0.25)
        assert sim.estimate == sim.truth


@pytest.fixture(scope="module")
def noisy_hover():
    sim = VehicleSim(VehicleConfig(), rng=np.random.default_rng(3))
    sim.set_armed(True)
    sim.set_setpoint(Setpoint(position=(0.0, 0.0, -1.5)))
    errors = []
    for _ in range(16):
        sim.run(0.5)
        t, e = sim.truth, sim.estimate
        errors.append((math.dist(t.position, e.position), math.dist(t.velocity, e.velocity),
                       att_error_deg(t.attitude, e.attitude)))
    return sim, np.array(errors)


def test_noisy_estimate_converges_and_stays_close(noisy_hover):
    sim, err = noisy_hover
    late = err[4:]  # after 2 s
    assert late[:, 0].max() < 0.02  # position (m); sensor noise 5 mm
    assert late[:, 1].max() < 0.05  # velocity (m/s)
    assert late[:, 2].max() < 1.0  # attitude (deg)
    assert sim.estimate != sim.truth  # really noisy


def test_gyro_bias_is_learned(noisy_hover):
    sim, _ = noisy_hover
    true_b = np.array(sim.imu.gyro_bias)
    est_b = np.array(sim.estimator.gyro_bias)
    assert np.linalg.norm(est_b - true_b) < 0.6 * np.linalg.norm(true_b)


def test_same_seed_same_estimate_different_seed_differs():
    def run(seed):
        sim = VehicleSim(VehicleConfig(), rng=np.random.default_rng(seed))
        sim.set_armed(True)
        sim.set_setpoint(Setpoint(position=(0.0, 0.0, -1.0)))
        sim.run(0.5)
        return sim.estimate

    assert run(11) == run(11)
    assert run(11) != run(12)


def test_reading_the_estimate_leaves_the_flight_as_it_was():
    """Telemetry, a heartbeat or a status check reads the estimate at moments the wall clock can choose (a
    ground station's heartbeat while lockstep holds time); the flight must not depend on them."""
    def fly(reads_per_step: float) -> list[bytes]:
        sim = VehicleSim(VehicleConfig(), rng=np.random.default_rng(7))
        sim.set_armed(True)
        readers = np.random.default_rng(1)
        states = []
        for target in ((0.0, 0.0, -1.5), (1.0, 0.3, -1.4)):
            sim.set_setpoint(Setpoint(position=target))
            for _ in range(400):
                if readers.random() < reads_per_step:
                    read = sim.estimate
                    assert read.attitude == sim.estimate.attitude   # a second read sees the same
                sim.step()
                states.append(np.asarray(sim.dyn.x).tobytes() + np.asarray(sim.estimator.q).tobytes())
        return states

    assert fly(0.0) == fly(0.3)


def test_kf_converges_from_wrong_initial_state_on_constant_velocity_track():
    noise = SensorNoise()
    rng = np.random.default_rng(5)
    est = Estimator(noise, rate_hz=100.0, physics_dt=0.002, position=(1.0, -1.0, 0.5))
    pose = PoseSensor(noise, rng)
    imu = Imu(SensorNoise(accel_bias_m_s2=0.0, gyro_bias_rad_s=0.0), rng)
    v = (1.0, 0.5, -0.2)
    q = (1.0, 0.0, 0.0, 0.0)
    for k in range(300):  # 3 s at 100 Hz, pose at 50 Hz
        t = (k + 1) * 0.01
        est.predict(imu.accel_mean(q, (0.0, 0.0, 0.0), 0.01, 5))
        if k % 2 == 1:
            p_meas, q_meas = pose.measure((v[0] * t, v[1] * t, v[2] * t), q)
            est.update_position(p_meas)
            est.correct_attitude(q_meas, 0.02)
    truth = (v[0] * t, v[1] * t, v[2] * t)
    assert math.dist(est.position, truth) < 0.02
    assert math.dist(est.velocity, v) < 0.05


def test_imu_noise_statistics_match_config():
    noise = SensorNoise(gyro_noise_rad_s=0.01, gyro_bias_rad_s=0.0)
    imu = Imu(noise, np.random.default_rng(0))
    g = np.array([imu.gyro((0.1, 0.0, 0.0)) for _ in range(5000)])
    assert g[:, 0].mean() == pytest.approx(0.1, abs=5e-4)
    assert g.std(axis=0) == pytest.approx([0.01] * 3, rel=0.05)
    # averaged accelerometer: level and still it reads -g on body z
    imu2 = Imu(SensorNoise(accel_noise_m_s2=0.0, accel_bias_m_s2=0.0), np.random.default_rng(0))
    assert imu2.accel_mean((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.01, 5) == pytest.approx((0.0, 0.0, -9.80665))


# --- the estimator as a pure unit: matrices, attitude propagation and correction, prediction, update ---------

from sitl_vehicle.airframes import GRAVITY  # noqa: E402


def quat_about(axis, angle):
    s = math.sin(0.5 * angle)
    return (math.cos(0.5 * angle), axis[0] * s, axis[1] * s, axis[2] * s)


def test_initial_state_and_defaults():
    noise = SensorNoise(accel_bias_m_s2=0.04, pos_noise_m=0.02)
    est = Estimator(noise, rate_hz=50.0, physics_dt=0.004, position=(1, -2, 3), attitude=(0, 1, 0, 0))
    assert est.noise is noise and est.att_gain == 0.05 and est.gyro_bias_gain == 0.5
    assert est.position == (1.0, -2.0, 3.0) and all(type(c) is float for c in est.position)
    assert est.q == (0.0, 1.0, 0.0, 0.0) and all(type(c) is float for c in est.q)
    assert est.velocity == (0.0, 0.0, 0.0) and est.acceleration == (0.0, 0.0, 0.0)
    assert est.gyro_bias == (0.0, 0.0, 0.0) and est.omega == (0.0, 0.0, 0.0) and est.accel_bias == (0.0, 0.0, 0.0)
    kf = est.kf
    np.testing.assert_array_equal(kf.x, [1.0, -2.0, 3.0, 0, 0, 0, 0, 0, 0])
    assert kf.x.dtype == float
    np.testing.assert_allclose(np.diag(kf.P), [0.05 ** 2] * 3 + [0.1 ** 2] * 3 + [0.04 ** 2] * 3, rtol=1e-12)
    assert np.count_nonzero(kf.P - np.diag(np.diag(kf.P))) == 0
    np.testing.assert_array_equal(kf.H, np.hstack([np.eye(3), np.zeros((3, 6))]))
    np.testing.assert_allclose(kf.R, 0.02 ** 2 * np.eye(3), rtol=1e-12)
    # a noiseless position sensor still gets a tiny R (the filter needs it invertible); a tiny accel bias a floor
    est0 = Estimator(SensorNoise(pos_noise_m=0.0, accel_bias_m_s2=0.0), 100.0, 0.002)
    np.testing.assert_allclose(est0.kf.R, 1e-8 * np.eye(3), rtol=1e-12)
    np.testing.assert_allclose(np.diag(est0.kf.P)[6:], [1e-6] * 3, rtol=1e-12)
    assert est0.q == (1.0, 0.0, 0.0, 0.0) and est0.position == (0.0, 0.0, 0.0)
    custom = Estimator(noise, 100.0, 0.002, att_gain=0.2, gyro_bias_gain=0.3)
    assert custom.att_gain == 0.2 and custom.gyro_bias_gain == 0.3


def test_prediction_matrices_follow_the_constant_acceleration_model_with_a_bias():
    noise = SensorNoise(accel_noise_m_s2=0.1)
    est = Estimator(noise, rate_hz=100.0, physics_dt=0.0025, accel_bias_walk=0.02)
    dt = 0.01
    assert est.dt == dt
    i3, z3 = np.eye(3), np.zeros((3, 3))
    # p' = p + dt v + dt^2/2 (u - b), v' = v + dt (u - b), b' = b
    f = np.block([[i3, dt * i3, -0.5 * dt * dt * i3], [z3, i3, -dt * i3], [z3, z3, i3]])
    b = np.vstack([0.5 * dt * dt * i3, dt * i3, z3])
    np.testing.assert_allclose(est.kf.F, f, rtol=1e-12, atol=0)
    np.testing.assert_allclose(est.kf.B, b, rtol=1e-12, atol=0)
    # white acceleration noise of the 4-sample mean (0.1 / 2), doubled, through B; the bias a random walk
    sa = 2.0 * 0.1 / 2.0
    q = sa ** 2 * b @ b.T
    q[6:, 6:] = 0.02 ** 2 * dt * i3
    np.testing.assert_allclose(est.kf.Q, q, rtol=1e-12, atol=0)
    # a slower estimator rate: new matrices, state and covariance kept
    est.kf.x[3] = 0.5
    p_before = est.kf.P.copy()
    est.set_rate(50.0)
    assert est.dt == 0.02 and est.kf.x[3] == 0.5
    np.testing.assert_array_equal(est.kf.P, p_before)
    assert est.kf.F[0, 3] == 0.02 and est.kf.B[3, 0] == 0.02
    sa = 2.0 * 0.1 / math.sqrt(8.0)
    assert est.kf.Q[3, 3] == pytest.approx(sa ** 2 * 0.02 ** 2, rel=1e-12)
    assert est.kf.Q[6, 6] == pytest.approx(0.02 ** 2 * 0.02, rel=1e-12)
    # fewer physics steps than one per interval count as one sample; tiny noise is floored at 1e-3 (x2)
    est = Estimator(SensorNoise(accel_noise_m_s2=0.1), rate_hz=100.0, physics_dt=0.05)
    assert est.kf.Q[3, 3] == pytest.approx((2.0 * 0.1) ** 2 * 0.01 ** 2, rel=1e-12)
    assert est.kf.Q[6, 6] == pytest.approx(0.01 ** 2 * 0.01, rel=1e-12)  # default bias walk 0.01
    est = Estimator(SensorNoise(accel_noise_m_s2=0.0), rate_hz=100.0, physics_dt=0.002)
    assert est.kf.Q[3, 3] == pytest.approx((2.0 * 1e-3) ** 2 * 0.01 ** 2, rel=1e-12)
    est = Estimator(SensorNoise(accel_noise_m_s2=0.1), rate_hz=100.0, physics_dt=0.004)  # 2.5 -> 2 samples
    assert est.kf.Q[3, 3] == pytest.approx((2.0 * 0.1 / math.sqrt(2.0)) ** 2 * 0.01 ** 2, rel=1e-12)


def test_gyro_delta_angle_is_accumulated_then_applied_as_one_exact_rotation():
    est = Estimator(SensorNoise(), 100.0, 0.002)
    est.gyro_bias = (0.1, -0.2, 0.05)
    est.add_gyro((0.1, -0.2, 1.05), 0.002)
    assert est.omega == pytest.approx((0.0, 0.0, 1.0), abs=1e-15)
    assert est.q == (1.0, 0.0, 0.0, 0.0)  # not propagated yet
    for _ in range(4):
        est.add_gyro((0.1, -0.2, 1.05), 0.002)
    est.propagate()
    assert est.q == pytest.approx(quat_about((0, 0, 1), 0.01), abs=1e-15)
    est.propagate()  # nothing accumulated: unchanged
    assert est.q == pytest.approx(quat_about((0, 0, 1), 0.01), abs=1e-15)
    # about a skew axis: exp map of the whole delta angle (not per-axis small steps)
    est = Estimator(SensorNoise(), 100.0, 0.002, attitude=quat_about((1, 0, 0), 0.3))
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    est.integrate_gyro(tuple(0.6 * axis), 1.0)
    expect = qmul(quat_about((1, 0, 0), 0.3), quat_about(axis, 0.6))
    assert est.q == pytest.approx(expect, abs=1e-12)
    assert est.omega == pytest.approx(tuple(0.6 * axis), abs=1e-15)
    assert math.fsum(c * c for c in est.q) == pytest.approx(1.0, abs=1e-15)
    # the rotation is applied in the body frame (right-multiplied)
    est = Estimator(SensorNoise(), 100.0, 0.002, attitude=quat_about((0, 0, 1), math.pi / 2))
    est.integrate_gyro((0.2, 0.0, 0.0), 1.0)
    assert est.q == pytest.approx(qmul(quat_about((0, 0, 1), math.pi / 2), quat_about((1, 0, 0), 0.2)), abs=1e-12)
    # per-axis accumulation: x, y and z each
    for k in range(3):
        est = Estimator(SensorNoise(), 100.0, 0.002)
        w = [0.0, 0.0, 0.0]
        w[k] = 0.5
        est.add_gyro(tuple(w), 0.1)
        est.add_gyro(tuple(w), 0.1)
        est.propagate()
        ax = [0.0, 0.0, 0.0]
        ax[k] = 1.0
        assert est.q == pytest.approx(quat_about(ax, 0.1), abs=1e-15)


def test_attitude_correction_moves_a_fraction_of_the_error_and_learns_the_bias():
    est = Estimator(SensorNoise(), 100.0, 0.002, att_gain=0.1, gyro_bias_gain=0.5)
    alpha = 0.2
    for axis in ((1, 0, 0), (0, 1, 0), (0, 0, 1)):
        est = Estimator(SensorNoise(), 100.0, 0.002, att_gain=0.1, gyro_bias_gain=0.5)
        est.correct_attitude(quat_about(axis, alpha), 0.02)
        ex = 2.0 * math.sin(0.5 * alpha)  # the small-angle error 2 * vector part
        # q <- q * (1, k e / 2): a rotation by 2 atan(k e / 2) about the error axis
        assert est.q == pytest.approx(quat_about(axis, 2.0 * math.atan(0.5 * 0.1 * ex)), abs=1e-12)
        assert est.gyro_bias == pytest.approx(tuple(-0.5 * 0.02 * ex * a for a in axis), abs=1e-15)
    # the measured quaternion's sign does not matter (q and -q are the same attitude)
    a = Estimator(SensorNoise(), 100.0, 0.002)
    b = Estimator(SensorNoise(), 100.0, 0.002)
    qm = quat_about((0.6, 0.0, 0.8), 0.3)
    a.correct_attitude(qm, 0.02)
    b.correct_attitude(tuple(-c for c in qm), 0.02)
    assert a.q == pytest.approx(b.q, abs=1e-15) and a.gyro_bias == pytest.approx(b.gyro_bias, abs=1e-15)
    assert a.q[0] > 0.99 and a.q[1] > 0.0 and a.q[3] > 0.0  # moved towards the measurement
    # the error is taken in the body frame of the current estimate
    est = Estimator(SensorNoise(), 100.0, 0.002, attitude=quat_about((0, 0, 1), math.pi / 2), att_gain=1.0)
    target = qmul(quat_about((0, 0, 1), math.pi / 2), quat_about((1, 0, 0), 0.1))
    est.correct_attitude(target, 0.02)
    ex = 2.0 * math.sin(0.05)
    assert est.q == pytest.approx(qmul(quat_about((0, 0, 1), math.pi / 2), quat_about((1, 0, 0),
                                                                                      2 * math.atan(0.5 * ex))),
                                  abs=1e-12)
    # pending gyro rotation is applied before the correction
    est = Estimator(SensorNoise(), 100.0, 0.002, att_gain=0.0, gyro_bias_gain=0.0)
    est.add_gyro((0.0, 0.0, 0.3), 1.0)
    est.correct_attitude((1.0, 0.0, 0.0, 0.0), 0.02)
    assert est.q == pytest.approx(quat_about((0, 0, 1), 0.3), abs=1e-15)
    # a perfect measurement changes nothing
    est = Estimator(SensorNoise(), 100.0, 0.002, attitude=quat_about((0, 1, 0), 0.4))
    est.correct_attitude(quat_about((0, 1, 0), 0.4), 0.02)
    assert est.q == pytest.approx(quat_about((0, 1, 0), 0.4), abs=1e-15) and est.gyro_bias == (0.0, 0.0, 0.0)


def test_predict_integrates_the_rotated_specific_force_plus_gravity():
    dt = 0.01
    est = Estimator(SensorNoise(), 1.0 / dt, 0.002, position=(1.0, 2.0, -3.0),
                    attitude=quat_about((0, 0, 1), math.pi / 2))  # yawed 90 deg: body x is north-east's east
    est.kf.x[6:9] = (0.1, 0.2, 0.3)  # an accelerometer bias estimate (NED)
    est.predict((1.0, 0.5, -GRAVITY - 2.0))  # body: forward 1, right 0.5, up 2 beyond hover
    u = np.array([-0.5, 1.0, -2.0])  # NED: body x -> east (+y), body y -> west (-x)
    acc = u - (0.1, 0.2, 0.3)
    assert est.acceleration == pytest.approx(tuple(acc), abs=1e-12)
    assert est.velocity == pytest.approx(tuple(dt * acc), abs=1e-12)
    assert est.position == pytest.approx(tuple(np.array([1.0, 2.0, -3.0]) + 0.5 * dt * dt * acc), abs=1e-12)
    assert est.accel_bias == pytest.approx((0.1, 0.2, 0.3)) and all(type(c) is float for c in est.accel_bias)
    # a pending gyro rotation is applied before the force is rotated
    est = Estimator(SensorNoise(), 100.0, 0.002)
    est.add_gyro((0.0, 0.0, math.pi / 2), 1.0)
    est.predict((1.0, 0.0, -GRAVITY))
    assert est.acceleration == pytest.approx((0.0, 1.0, 0.0), abs=1e-12)
    assert est.q == pytest.approx(quat_about((0, 0, 1), math.pi / 2), abs=1e-12)


def test_position_update_pulls_towards_the_measurement_by_the_kalman_gain():
    noise = SensorNoise(pos_noise_m=0.05)
    est = Estimator(noise, 100.0, 0.002, position=(0.0, 0.0, -1.0))
    est.update_position((0.1, -0.2, -0.7))
    # P = 0.05^2, R = 0.05^2, no cross-covariance yet: halfway, velocity unchanged
    assert est.position == pytest.approx((0.05, -0.1, -0.85), abs=1e-12)
    assert est.velocity == (0.0, 0.0, 0.0)
    np.testing.assert_allclose(np.diag(est.kf.P)[:3], [0.05 ** 2 / 2] * 3, rtol=1e-9)
    # the acceleration published after an update uses the last prediction's input
    est = Estimator(SensorNoise(pos_noise_m=0.0), 100.0, 0.002)
    est.predict((0.5, 0.0, -GRAVITY))
    est.update_position((0.2, 0.0, 0.0))
    assert est.acceleration[0] == pytest.approx(0.5 - est.accel_bias[0], abs=1e-12)
    assert est.position[0] == pytest.approx(0.2, abs=1e-5)  # a near-perfect sensor: R = 1e-8
    assert est.velocity[0] > 0.5 * 0.01  # the correlated velocity moves along


def test_propagation_renormalises_the_attitude():
    """A non-unit attitude (here twice a unit one) comes out of the next propagation as a unit quaternion:
    the same rotation as from the unit one."""
    axis = np.array([0.48, 0.6, 0.64])  # a unit axis with every component non-zero
    est = Estimator(SensorNoise(), 100.0, 0.002, attitude=(2.0 * 0.8, 2.0 * 0.6, 0.0, 0.0))
    est.integrate_gyro(tuple(0.4 * axis), 1.0)
    expect = qmul((0.8, 0.6, 0.0, 0.0), quat_about(axis, 0.4))
    assert est.q == pytest.approx(expect, abs=1e-12)


def test_attitude_correction_sign_and_bias_axes():
    # the measurement's sign flipped, about an axis with every component non-zero: the same correction
    axis = (0.48, 0.6, 0.64)
    qm = quat_about(axis, 0.3)
    a = Estimator(SensorNoise(), 100.0, 0.002)
    b = Estimator(SensorNoise(), 100.0, 0.002)
    a.correct_attitude(qm, 0.02)
    b.correct_attitude(tuple(-c for c in qm), 0.02)
    assert a.q == pytest.approx(b.q, abs=1e-15) and a.gyro_bias == pytest.approx(b.gyro_bias, abs=1e-15)
    ex = 2.0 * math.sin(0.15)
    assert a.gyro_bias == pytest.approx(tuple(-0.5 * 0.02 * ex * c for c in axis), abs=1e-15)
    # the bias learnt adds to the current one, axis by axis
    est = Estimator(SensorNoise(), 100.0, 0.002, gyro_bias_gain=0.5)
    est.gyro_bias = (0.1, -0.2, 0.3)
    est.correct_attitude(qm, 0.02)
    assert est.gyro_bias == pytest.approx(tuple(b0 - 0.5 * 0.02 * ex * c for b0, c in zip((0.1, -0.2, 0.3), axis,
                                                                                          strict=True)), abs=1e-15)
    # an error of exactly 180 deg (e = (0, 1, 0, 0)) is used as it is: the correction turns about +x
    est = Estimator(SensorNoise(), 100.0, 0.002, att_gain=0.1)
    est.correct_attitude((0.0, 1.0, 0.0, 0.0), 0.02)
    assert est.q == pytest.approx(quat_about((1, 0, 0), 2.0 * math.atan(0.5 * 0.1 * 2.0)), abs=1e-12)
    assert est.gyro_bias == pytest.approx((-0.5 * 0.02 * 2.0, 0.0, 0.0), abs=1e-15)
