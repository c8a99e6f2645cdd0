import numpy as np

from companion.flow.colour import colour_wheel, flow_to_colour


def test_wheel_has_baker_segments():
    wheel = colour_wheel()
    assert wheel.shape == (55, 3)
    np.testing.assert_array_equal(wheel[0], [255, 0, 0])        # RY starts at red
    np.testing.assert_array_equal(wheel[15], [255, 255, 0])     # YG starts at yellow
    np.testing.assert_array_equal(wheel[21], [0, 255, 0])       # GC starts at green
    np.testing.assert_array_equal(wheel[25], [0, 255, 255])     # CB starts at cyan
    np.testing.assert_array_equal(wheel[36], [0, 0, 255])       # BM starts at blue
    np.testing.assert_array_equal(wheel[49], [255, 0, 255])     # MR starts at magenta
    assert wheel[14, 1] == np.floor(255 * 14 / 15)


def test_zero_flow_is_white():
    out = flow_to_colour(np.zeros((5, 7, 2), np.float32))
    assert out.dtype == np.uint8 and out.shape == (5, 7, 3)
    assert (out == 255).all()


def test_largest_plus_u_is_pure_red_and_normalised_per_frame():
    flow = np.zeros((3, 3, 2), np.float32)
    flow[1, 1] = (7.0, 0.0)
    flow[0, 0] = (0.0, 3.5)                  # half the largest magnitude, pointing down (+v)
    rgb = flow_to_colour(flow)
    np.testing.assert_array_equal(rgb[1, 1], [255, 0, 0])
    assert (rgb[2, 2] == 255).all()
    # +v maps to angle 0.5 -> index 13.5 -> between wheel[13] and wheel[14]; half saturation
    wheel = colour_wheel() / 255
    col = 0.5 * wheel[13] + 0.5 * wheel[14]
    expected = np.floor(255 * (1 - 0.5 * (1 - col)))
    np.testing.assert_allclose(rgb[0, 0], expected, atol=1)
    bgr = flow_to_colour(flow, bgr=True)
    np.testing.assert_array_equal(bgr[1, 1], [0, 0, 255])


def test_minus_u_is_cyan_and_minus_v_is_blue_magenta():
    flow = np.zeros((1, 3, 2), np.float32)
    flow[0, 0] = (-1.0, 0.0)      # angle 0 -> wheel index 27 (CB: green fading, blue full)
    flow[0, 1] = (0.0, -1.0)      # angle -0.5 -> index 40.5 (BM: red rising, blue full)
    rgb = flow_to_colour(flow)[0].astype(float)
    wheel = colour_wheel()
    np.testing.assert_allclose(rgb[0], wheel[27], atol=1)
    np.testing.assert_allclose(rgb[1], 0.5 * wheel[40] + 0.5 * wheel[41], atol=1)
    assert (rgb[2] == 255).all()  # zero flow stays white


def test_non_finite_flow_is_black_and_ignored_for_normalisation():
    flow = np.zeros((1, 2, 2), np.float32)
    flow[0, 0] = (np.nan, 0.0)
    flow[0, 1] = (2.0, 0.0)
    rgb = flow_to_colour(flow)
    assert (rgb[0, 0] == 0).all()
    np.testing.assert_array_equal(rgb[0, 1], [255, 0, 0])
