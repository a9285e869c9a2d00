"""``gradient_norm`` against numpy's ``sqrt(sum(g**2 for g in gradient(a, *steps)))``, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.model.slope import gradient_norm


def numpy_norm(a: np.ndarray, steps) -> np.ndarray:
    h = steps if isinstance(steps, tuple) else (steps,)
    with np.errstate(invalid="ignore", over="ignore"):
        return np.sqrt(sum(g**2 for g in np.gradient(a, *h)))


def same_bits(x: np.ndarray, y: np.ndarray) -> bool:
    return x.shape == y.shape and x.tobytes() == y.tobytes()


@pytest.mark.parametrize("shape", [(24, 24, 24), (2, 3, 5), (7, 2, 9), (20, 20, 20)])
@pytest.mark.parametrize("steps", [0.1, (0.05, 0.3, 1.7), 1e-300])
def test_the_bits_of_numpy(shape, steps) -> None:
    rng = np.random.default_rng(7)
    a = rng.normal(size=shape) * 10.0 ** rng.integers(-5, 6, size=shape)
    a.flat[rng.integers(0, a.size, size=max(a.size // 20, 1))] = np.nan
    a.flat[rng.integers(0, a.size, size=max(a.size // 40, 1))] = np.inf
    a.flat[rng.integers(0, a.size, size=max(a.size // 40, 1))] = -np.inf
    a.flat[rng.integers(0, a.size, size=max(a.size // 40, 1))] = 1e308  # overflows squared
    with np.errstate(invalid="ignore", over="ignore"):
        assert same_bits(gradient_norm(a, steps), numpy_norm(a, steps))


def test_read_only_and_strided_samples() -> None:
    x = np.linspace(-1.0, 1.0, 17)
    a = np.sin(3 * x)[:, None, None] * np.cos(x)[None, :, None] + x[None, None, :] ** 2
    view = np.asfortranarray(a)
    view.setflags(write=False)
    assert same_bits(gradient_norm(view, 0.125), numpy_norm(a, 0.125))
    a.setflags(write=False)
    assert same_bits(gradient_norm(a, (0.125, 0.125, 0.125)), numpy_norm(a, 0.125))
    assert a.flags.writeable is False  # the caller's array untouched


def test_other_arrays_go_to_numpy() -> None:
    flat = np.arange(5.0)
    assert same_bits(np.asarray(gradient_norm(flat, 0.5)), np.asarray(numpy_norm(flat, 0.5)))
    ints = np.arange(27).reshape(3, 3, 3)
    assert same_bits(gradient_norm(ints, 1.0), numpy_norm(ints, 1.0))
    with pytest.raises(ValueError, match="too small"):
        gradient_norm(np.zeros((1, 4, 4)), 1.0)
