"""Synthetic camera rendering: field background, shaded ball, distortion, blur, noise."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog.camera import Camera, look_at
from pslog.errors import InputError
from pslog.rig import builtin_rig
from recorders.detect import BallDetector
from recorders.render import CameraRenderer, RenderOptions, render_background


@pytest.fixture(scope="module")
def paper_cam() -> Camera:
    return builtin_rig("paper3").cameras[1]


def _pixel(frame: np.ndarray, uv: np.ndarray) -> np.ndarray:
    u, v = np.round(uv).astype(int)
    return frame[v, u].astype(int)


def test_background_shows_lines_on_green_carpet(paper_cam):
    bg = render_background(paper_cam, RenderOptions())
    assert bg.shape == (480, 640, 3) and bg.dtype == np.uint8
    uv, _ = paper_cam.project(np.array([[1.5, 0.6, 0.0], [0.75, 0.5, 0.0], [0.75, 1.5, 0.0]]))
    line, carpet1, carpet2 = (_pixel(bg, p) for p in uv)
    assert np.all(line > 180)  # centre line x = 1.5: white
    for carpet in (carpet1, carpet2):
        b, g, r = carpet
        assert g > b + 40 and g > r + 40  # green
    assert bg[..., 1].std() > 3  # textured, not flat


def test_ball_drawn_at_its_projection_with_its_size(paper_cam):
    renderer = CameraRenderer(paper_cam, RenderOptions(noise_sigma=0.0, exposure_s=0.0))
    center = np.array([1.5, 1.0, 0.5])
    frame = renderer.render_positions(center[None])
    changed = np.any(frame != renderer.background, axis=2)
    uv, _ = paper_cam.project(center[None])
    b, g, r = _pixel(frame, uv[0])
    assert r > 150 and r > g + 60 and g > b  # orange
    radius = renderer.apparent_radius_px(center)
    # anti-aliased edge pixels count as changed: compare with a disc one pixel larger
    assert np.pi * (radius - 0.5) ** 2 < changed.sum() < np.pi * (radius + 1.5) ** 2
    vs, us = np.nonzero(changed)
    assert_allclose([us.mean(), vs.mean()], uv[0], atol=0.5)


def test_ball_follows_lens_distortion():
    R, t = look_at((1.5, -0.5, 1.8), (1.5, 1.0, 0.0))
    K = np.array([[700.0, 0.0, 319.5], [0.0, 700.0, 239.5], [0.0, 0.0, 1.0]])
    cam = Camera("fisheyeish", 640, 480, K, np.array([-0.3, 0.1, 0.0, 0.0, 0.0]), R, t)
    ideal = cam.replace(dist=np.zeros(5))
    renderer = CameraRenderer(cam, RenderOptions(noise_sigma=0.0, exposure_s=0.0))
    center = np.array([0.6, 0.5, 0.1])  # near the image corner: strong distortion
    found = BallDetector().detect(renderer.render_positions(center[None]))
    uv, _ = cam.project(center[None])
    uv_ideal, _ = ideal.project(center[None])
    assert np.linalg.norm(uv - uv_ideal) > 20  # distortion matters here ...
    assert_allclose(found.uv[0], uv[0], atol=0.3)  # ... and the render follows it


def test_motion_blur_spreads_the_ball_along_its_path():
    R, t = look_at((1.5, -0.5, 1.8), (1.5, 1.0, 0.0))
    K = np.array([[700.0, 0.0, 319.5], [0.0, 700.0, 239.5], [0.0, 0.0, 1.0]])
    cam = Camera("close", 640, 480, K, np.zeros(5), R, t)
    renderer = CameraRenderer(cam, RenderOptions(noise_sigma=0.0, exposure_s=0.02))

    def position(t):  # 4 m/s along x: a horizontal smear in this camera
        return np.stack([1.5 + 4.0 * t, np.full_like(t, 1.0), np.full_like(t, 0.3)], axis=1)

    frame = renderer.render(position, 0.0)
    ends, _ = cam.project(position(np.array([-0.01, 0.01])))
    path_px = ends[1, 0] - ends[0, 0]
    radius = renderer.apparent_radius_px(position(np.array([0.0]))[0])
    assert path_px > 3 * radius
    weight = np.abs(frame.astype(float) - renderer.background).sum(axis=2)
    vs, us = np.nonzero(weight > 0)
    assert_allclose(us.max() - us.min() + 1, path_px + 2 * radius, atol=2.0)
    assert_allclose(vs.max() - vs.min() + 1, 2 * radius, atol=2.0)
    # the smear is centred on the ball at the exposure's centre (the frame's timestamp)
    vv, uu = np.mgrid[:frame.shape[0], :frame.shape[1]]
    centroid = [np.sum(uu * weight) / weight.sum(), np.sum(vv * weight) / weight.sum()]
    assert_allclose(centroid, ends.mean(axis=0), atol=0.5)


def test_noise_is_reproducible_per_frame(paper_cam):
    renderer = CameraRenderer(paper_cam, RenderOptions(noise_sigma=3.0), camera_index=2)
    center = np.array([[1.5, 1.0, 0.5]])
    a, b, a2 = (renderer.render_positions(center, k) for k in (7, 8, 7))
    assert_array_equal(a, a2)
    diff = a.astype(float) - b.astype(float)
    assert 0.8 * 3.0 * np.sqrt(2) < diff.std() < 1.2 * 3.0 * np.sqrt(2)


def test_ball_behind_the_camera_is_not_drawn(paper_cam):
    renderer = CameraRenderer(paper_cam, RenderOptions(noise_sigma=0.0))
    behind = paper_cam.center_world - 0.5 * paper_cam.R[2]
    assert_array_equal(renderer.render_positions(behind[None]), renderer.background)


def test_options_validated():
    for bad in ({"ball_radius": 0.0}, {"exposure_s": -1.0}, {"noise_sigma": float("nan")},
                {"supersample": 0}):
        with pytest.raises(InputError):
            RenderOptions(**bad)


def test_a_background_is_rendered_once_and_read_back_from_disk_the_same(tmp_path,
                                                                         monkeypatch):
    """Every synthetic camera process renders its background (~1.2 M rays); the disk cache
    gives the same bytes, and a bad cache (corrupt file, wrong size, unwritable folder,
    disabled) is never an error: the background is rendered."""
    import recorders.render as render

    cam = builtin_rig("paper3").cameras[2].replace(width=160, height=120)
    options = RenderOptions(seed=11)
    expected = render._trace_background(cam, options)

    def fresh():
        render._BACKGROUNDS.clear()
        return render_background(cam, options)

    monkeypatch.setenv("PSLOG_CACHE_DIR", str(tmp_path / "cache"))
    assert_array_equal(fresh(), expected)
    (stored,) = (tmp_path / "cache" / "backgrounds").glob("*.npy")
    assert_array_equal(np.load(stored), expected)
    # read back (not rendered): a file of the right shape is used as it is
    marked = expected.copy()
    marked[0, 0] = (1, 2, 3)
    np.save(stored, marked)
    got = fresh()
    assert_array_equal(got, marked) and not got.flags.writeable
    # a corrupt file and a file of another size are rendered again (and replaced)
    for bad in (b"not a numpy file", b"PK\x03\x04 not a zip", "zip", None):
        if bad is None:
            np.save(stored, np.zeros((4, 4, 3), np.uint8))
        elif bad == "zip":  # np.load gives an NpzFile, no array
            with open(stored, "wb") as f:
                np.savez(f, a=expected)
        else:
            stored.write_bytes(bad)
        assert_array_equal(fresh(), expected)
        assert_array_equal(np.load(stored), expected)
    # other options: another file
    render._BACKGROUNDS.clear()
    render_background(cam, RenderOptions(seed=12))
    assert len(list((tmp_path / "cache" / "backgrounds").glob("*.npy"))) == 2
    # a folder that cannot be written (a file where it would be), or the cache off
    (tmp_path / "blocked").write_text("a file")
    monkeypatch.setenv("PSLOG_CACHE_DIR", str(tmp_path / "blocked"))
    assert_array_equal(fresh(), expected)
    monkeypatch.setenv("PSLOG_CACHE_DIR", "")
    assert render._background_file(("any",)) is None
    monkeypatch.setenv("PSLOG_CACHE_DIR", "relative/cache")  # never the working folder
    assert render._background_file(("any",)) is None
    assert_array_equal(fresh(), expected)
    assert not list(tmp_path.glob("**/.partial-*"))
