from __future__ import annotations

import math
from collections.abc import Callable
from typing import cast

import numpy as np
import pytest

from cpf_env.model.paths import (
    CIRCLE,
    LEMNISCATE,
    LINE,
    PATH_PARAM_SIZE,
    SINUSOID,
    Circle,
    Lemniscate,
    Path,
    Sinusoid,
    StraightLine,
    encode_paths,
    evaluate_paths,
    path_point,
)

PATHS: dict[str, Path] = {
    "line": StraightLine(x0=3.0, y0=-2.0, heading=2.3),
    "line_default": StraightLine(),
    "circle_ccw": Circle(cx=1.0, cy=-4.0, radius=6.0, phase=0.7),
    "circle_cw": Circle(cx=-3.0, cy=2.0, radius=4.0, phase=-2.5, clockwise=True),
    "sinusoid_paper": Sinusoid(y0=5.0, amplitude=2.0, wavenumber=0.2),
    "sinusoid_rotated": Sinusoid(
        x0=-1.0, y0=2.0, amplitude=1.5, wavenumber=0.6, phase=1.1, heading=-2.0
    ),
    "lemniscate": Lemniscate(cx=2.0, cy=1.0, half_width=8.0, heading=0.9),
    "lemniscate_small": Lemniscate(half_width=3.0, heading=-2.8),
}
THETA = np.linspace(-40.0, 60.0, 401)
STEP = 1e-5


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def _speed(path: Path, theta: np.ndarray) -> np.ndarray:
    first = path.evaluate(theta)[..., 1, :2]
    return np.hypot(first[..., 0], first[..., 1])


@pytest.mark.parametrize("name", PATHS)
def test_derivatives_match_finite_differences(name: str) -> None:
    path = PATHS[name]
    mid, plus, minus = (
        path.evaluate(THETA),
        path.evaluate(THETA + STEP),
        path.evaluate(THETA - STEP),
    )
    d_point = (plus[:, 0] - minus[:, 0]) / (2.0 * STEP)
    d_point[:, 2] = _wrap(plus[:, 0, 2] - minus[:, 0, 2]) / (2.0 * STEP)
    d_first = (plus[:, 1] - minus[:, 1]) / (2.0 * STEP)
    for order, numeric in ((1, d_point), (2, d_first)):
        analytic = mid[:, order]
        scale = 1.0 + np.abs(analytic).max(axis=0)
        np.testing.assert_allclose(numeric, analytic, rtol=0.0, atol=1e-6 * scale.max())
    # A zero check is too weak: the curved kinds must have curvature to test against.
    if not isinstance(path, StraightLine):
        assert np.abs(mid[:, 2]).max() > 1e-2


@pytest.mark.parametrize("name", PATHS)
def test_heading_follows_tangent(name: str) -> None:
    out = PATHS[name].evaluate(THETA)
    tangent = out[:, 1, :2] / np.linalg.norm(out[:, 1, :2], axis=1, keepdims=True)
    np.testing.assert_allclose(np.cos(out[:, 0, 2]), tangent[:, 0], atol=1e-12)
    np.testing.assert_allclose(np.sin(out[:, 0, 2]), tangent[:, 1], atol=1e-12)
    assert np.all(np.abs(out[:, 0, 2]) <= np.pi)


@pytest.mark.parametrize("name", ["line", "line_default", "circle_ccw", "circle_cw"])
def test_line_and_circle_are_unit_speed(name: str) -> None:
    np.testing.assert_allclose(_speed(PATHS[name], THETA), 1.0, atol=1e-12)


def test_line_formula() -> None:
    out = PATHS["line"].evaluate(THETA)
    np.testing.assert_allclose(out[:, 0, 0], 3.0 + THETA * math.cos(2.3), atol=1e-12)
    np.testing.assert_allclose(out[:, 0, 1], -2.0 + THETA * math.sin(2.3), atol=1e-12)
    np.testing.assert_allclose(out[:, 0, 2], 2.3, atol=1e-12)
    np.testing.assert_array_equal(out[:, 1:, 2], 0.0)


@pytest.mark.parametrize(("name", "sign"), [("circle_ccw", 1.0), ("circle_cw", -1.0)])
def test_circle_geometry_and_curvature(name: str, sign: float) -> None:
    path = PATHS[name]
    assert isinstance(path, Circle)
    out = path.evaluate(THETA)
    angle = path.phase + sign * THETA / path.radius
    np.testing.assert_allclose(out[:, 0, 0], path.cx + path.radius * np.cos(angle), atol=1e-12)
    np.testing.assert_allclose(out[:, 0, 1], path.cy + path.radius * np.sin(angle), atol=1e-12)
    np.testing.assert_allclose(out[:, 1, 2], sign / path.radius, atol=1e-14)
    np.testing.assert_allclose(out[:, 2, 2], 0.0, atol=1e-14)
    period = path.evaluate(THETA + 2.0 * np.pi * path.radius)
    np.testing.assert_allclose(period[:, 0, :2], out[:, 0, :2], atol=1e-9)


def test_paper_sinusoid() -> None:
    theta = np.linspace(0.0, 300.0, 30001)
    out = Sinusoid(y0=-3.0, amplitude=2.0, wavenumber=0.2).evaluate(theta)
    np.testing.assert_allclose(out[:, 0, 0], theta, atol=1e-12)
    np.testing.assert_allclose(out[:, 0, 1], -3.0 + 2.0 * np.sin(0.2 * theta), atol=1e-12)
    speed = np.hypot(out[:, 1, 0], out[:, 1, 1])
    assert speed.min() >= 1.0 - 1e-12
    assert speed.max() <= 1.08
    np.testing.assert_allclose(speed.max(), math.sqrt(1.16), atol=1e-6)


def test_sinusoid_speed_bounds() -> None:
    path = PATHS["sinusoid_rotated"]
    assert isinstance(path, Sinusoid)
    speed = _speed(path, THETA)
    upper = math.sqrt(1.0 + (path.amplitude * path.wavenumber) ** 2)
    assert speed.min() >= 1.0 - 1e-12
    assert speed.max() <= upper + 1e-12


@pytest.mark.parametrize("name", ["lemniscate", "lemniscate_small"])
def test_lemniscate_is_closed_and_speed_bounded(name: str) -> None:
    path = PATHS[name]
    assert isinstance(path, Lemniscate)
    period = 2.0 * np.pi * path.half_width
    theta = np.linspace(0.0, period, 20001)
    out = path.evaluate(theta)
    speed = np.hypot(out[:, 1, 0], out[:, 1, 1])
    assert speed.min() >= math.sqrt(7.0) / 4.0 - 1e-12
    assert speed.max() <= math.sqrt(2.0) + 1e-12
    assert 0.5 < speed.min() < 0.67 and 1.41 < speed.max() < 1.5
    np.testing.assert_allclose(out[-1], out[0], atol=1e-9)
    np.testing.assert_allclose(out[0, 0, :2], [path.cx, path.cy], atol=1e-12)  # the crossing


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: Circle(radius=0.0), "radius must be > 0"),
        (lambda: Circle(radius=-2.0), "radius must be > 0"),
        (lambda: Circle(radius=math.nan), "radius must be a finite number"),
        (lambda: Circle(radius=1.0, clockwise=cast(bool, 1)), "clockwise must be True or False"),
        (lambda: StraightLine(x0=math.inf), "x0 must be a finite number"),
        (lambda: StraightLine(heading=cast(float, "north")), "heading must be a finite number"),
        (lambda: StraightLine(y0=True), "y0 must be a finite number"),
        (lambda: Sinusoid(amplitude=2.0, wavenumber=0.0), "wavenumber must be > 0"),
        (lambda: Sinusoid(amplitude=-1.0, wavenumber=0.2), "amplitude must be >= 0"),
        (lambda: Sinusoid(amplitude=1.0, wavenumber=0.2, phase=-math.inf), "phase must be"),
        (lambda: Lemniscate(half_width=0.0), "half_width must be > 0"),
        (lambda: Lemniscate(half_width=5.0, cy=math.nan), "cy must be a finite number"),
    ],
)
def test_invalid_parameters_raise(make: Callable[[], Path], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make()


def test_fields_are_coerced_and_keyword_only() -> None:
    circle = Circle(radius=np.int64(3), clockwise=np.bool_(True))  # type: ignore[arg-type]
    assert type(circle.radius) is float and circle.clockwise is True
    with pytest.raises(TypeError):
        Circle(0.0, 0.0, 1.0)  # type: ignore[call-arg]


def test_encode_layout() -> None:
    assert {StraightLine.kind, Circle.kind, Sinusoid.kind, Lemniscate.kind} == {
        LINE,
        CIRCLE,
        SINUSOID,
        LEMNISCATE,
    }
    for path in PATHS.values():
        params = path.encode()
        assert params.shape == (PATH_PARAM_SIZE,) and params.dtype == np.float64
    assert Circle(radius=2.0, clockwise=True).encode()[4] == -1.0


def test_evaluate_shapes() -> None:
    path = PATHS["lemniscate"]
    assert path.evaluate(1.5).shape == (3, 3)
    assert path.evaluate(THETA).shape == (THETA.size, 3, 3)
    grid = THETA[:24].reshape(2, 3, 4)
    out = path.evaluate(grid)
    assert out.shape == (2, 3, 4, 3, 3)
    np.testing.assert_array_equal(out.reshape(-1, 3, 3), path.evaluate(grid.ravel()))
    assert path.evaluate(np.empty(0)).shape == (0, 3, 3)


@pytest.mark.parametrize("name", PATHS)
def test_batch_is_bit_identical_to_single_calls(name: str) -> None:
    path = PATHS[name]
    theta = THETA[::17]
    batch = path.evaluate(theta)
    single = np.empty((3, 3))
    for k, value in enumerate(theta):
        np.testing.assert_array_equal(batch[k], path.evaluate(value))
        path_point(path.kind, path.encode(), float(value), single)
        np.testing.assert_array_equal(batch[k], single)


def test_encode_paths_round_trip() -> None:
    paths = list(PATHS.values())
    kinds, params = encode_paths(paths)
    assert kinds.dtype == np.int64 and kinds.shape == (len(paths),)
    assert params.dtype == np.float64 and params.shape == (len(paths), PATH_PARAM_SIZE)
    rng = np.random.default_rng(0)
    theta = rng.uniform(-50.0, 50.0, size=len(paths))
    mixed = evaluate_paths(kinds, params, theta)
    for k, path in enumerate(paths):
        np.testing.assert_array_equal(mixed[k], path.evaluate(theta[k]))
    empty_kinds, empty_params = encode_paths([])
    assert empty_kinds.shape == (0,) and empty_params.shape == (0, PATH_PARAM_SIZE)
    with pytest.raises(TypeError, match="Path instances"):
        encode_paths([PATHS["line"], "circle"])  # type: ignore[list-item]


def test_evaluate_paths_rejects_bad_input() -> None:
    kinds, params = encode_paths([PATHS["line"], PATHS["circle_cw"]])
    with pytest.raises(ValueError, match="evaluate_paths"):
        evaluate_paths(kinds, params, np.zeros(3))
    with pytest.raises(ValueError, match="unknown path kind"):
        evaluate_paths(np.array([7], dtype=np.int64), params[:1], np.zeros(1))
