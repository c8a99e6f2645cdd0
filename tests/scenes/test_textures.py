import numpy as np
import pytest

from scenes.spec import ALL_TEXTURES
from scenes.textures import make_texture


@pytest.mark.parametrize("kind", ALL_TEXTURES)
def test_texture_deterministic_per_seed(kind):
    a = make_texture(kind, 3, 1.0, 0.8, px_per_m=100)
    b = make_texture(kind, 3, 1.0, 0.8, px_per_m=100)
    c = make_texture(kind, 4, 1.0, 0.8, px_per_m=100)
    assert a.shape == (80, 100, 3) and a.dtype == np.float32
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert 0.0 <= a.min() and a.max() <= 1.0
    assert a.std() > 0.02  # textured, not flat (plaster is deliberately weak)


def test_unknown_texture():
    with pytest.raises(ValueError, match="unknown texture"):
        make_texture("marble", 0, 1, 1)
