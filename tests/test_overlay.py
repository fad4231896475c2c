"""Overlay video: frames re-read at the analysis rate, bodies drawn where the camera sees them."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from physpose.errors import PhysposeError
from physpose.reconstruction import Reconstruction
from physpose.render.draw import project
from physpose.render.overlay import (COLORS, FORCE_COLOR, RESTART_COLOR, OverlayConfig,
                                     render_overlay, save_overlay_png)
from synthetic_result import FPS, IMAGE_SIZE, make_reconstruction, write_video

CFG = OverlayConfig(height=240)  # panel height = the synthetic video's height: scale 1
SOURCE_FPS = 30.0


@pytest.fixture(scope="module")
def result_with_video(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("overlay")
    video = write_video(tmp / "in.mp4", 60, fps=SOURCE_FPS)
    n = 20
    indices = np.floor(np.arange(n) / FPS * SOURCE_FPS + 0.5).astype(int) + 5
    rec = make_reconstruction(num_frames=n, meta={"source": str(video),
                                                  "frame_indices": indices.tolist()})
    rec.save(tmp / "result" / "reconstruction.npz")
    return tmp / "result", video, indices


def _source_frames(video):
    cap = cv2.VideoCapture(str(video))
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            return frames
        frames.append(f)


def test_video_has_every_frame_at_the_analysis_rate(result_with_video, tmp_path):
    folder, _, indices = result_with_video
    made = render_overlay(folder, out=tmp_path / "o.mp4", cfg=CFG)
    cap = cv2.VideoCapture(str(made.path))
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(FPS)
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == len(indices)
    w, h = IMAGE_SIZE
    assert int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)) == h
    assert int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)) == w + round(h * 4 / 3)
    assert made.background.endswith("in.mp4")
    assert not list(tmp_path.glob(".*tmp*")), "temporary file left behind"


def test_png_frame_shows_the_source_frame_it_was_analysed_from(result_with_video, tmp_path):
    folder, video, indices = result_with_video
    source = _source_frames(video)
    t = 7
    png = cv2.imread(str(save_overlay_png(folder, t, tmp_path / "f.png", cfg=CFG)))
    w, h = IMAGE_SIZE
    patch = (slice(h - 30, h), slice(w - 60, w))  # bottom-right corner: no body, no legend
    errors = [np.abs(png[patch].astype(int) - f[patch].astype(int)).mean() for f in source]
    assert int(np.argmin(errors)) == indices[t] and min(errors) < 1.0


def test_bodies_are_drawn_where_the_camera_projects_them(tmp_path):
    rec = make_reconstruction(num_frames=6, meta={"image_size": list(IMAGE_SIZE)})
    rec.save(tmp_path / "r" / "reconstruction.npz")
    png = cv2.imread(str(save_overlay_png(tmp_path / "r", 3, tmp_path / "f.png", cfg=CFG)))
    video_panel = png[:, : IMAGE_SIZE[0]]
    background = video_panel[-1, IMAGE_SIZE[0] // 2].astype(int)
    (px, _), front = project(rec.camera_K, rec.camera_T_world2cam, rec.joints_physics[3, :2])
    assert front.all()
    thorax = np.round(px).astype(int)  # the pelvis->spine bone passes here
    assert np.abs(video_panel[thorax[1], thorax[0]].astype(int) - background).sum() > 60
    # Both motions share the root here: a joint dot of a motion colour covers the pelvis.
    x, y = np.round(project(rec.camera_K, rec.camera_T_world2cam,
                            rec.joints_physics[3, 0])[0]).astype(int)
    near = video_panel[y - 1:y + 2, x - 1:x + 2].reshape(-1, 3).astype(int)
    assert min(np.abs(near - np.array(c)).sum(axis=1).min() for c in COLORS.values()) < 30
    # The 3d view is not empty: its pixels vary (grid and body).
    assert png[:, IMAGE_SIZE[0]:].std() > 5


def test_a_physics_restart_is_announced_on_the_frames_after_it(tmp_path):
    rec = make_reconstruction(num_frames=30, meta={"dynamics": {"restarts": [10]}})
    rec.save(tmp_path / "r" / "reconstruction.npz")
    rows = 4  # the legend: two motions, foot contact, ground force
    notice = (slice(36 + 20 * rows + 4, 36 + 20 * rows + 20), slice(8, 290))  # below it
    red = np.array(RESTART_COLOR)

    def shown(t):
        png = cv2.imread(str(save_overlay_png(tmp_path / "r", t, tmp_path / "f.png", cfg=CFG)))
        return (np.abs(png[notice].astype(int) - red).sum(axis=-1) < 30).mean() > 0.5

    # 0.4 s at 25 fps: frames 10-19 carry the notice, not the frames before or after.
    assert [shown(t) for t in (9, 10, 19, 20)] == [False, True, True, False]


def test_kinematic_only_result_without_body_or_video(tmp_path):
    rec = make_reconstruction(num_frames=4, physics=False, qpos_kinematic=False, meta={})
    rec.save(tmp_path / "r" / "reconstruction.npz")
    made = render_overlay(tmp_path / "r", cfg=CFG)
    assert made.path == tmp_path / "r" / "overlay.mp4" and made.path.stat().st_size > 0
    assert "plain background" in made.background
    png = cv2.imread(str(save_overlay_png(tmp_path / "r", 2, tmp_path / "f.png", cfg=CFG)))
    x, y = np.round(project(rec.camera_K, rec.camera_T_world2cam,
                            rec.joints_kinematic[2, 0])[0]).astype(int)
    assert np.abs(png[y, x].astype(int) - COLORS["kinematic"]).sum() < 30


def test_bad_inputs_are_clear_errors(result_with_video, tmp_path):
    folder, _, _ = result_with_video
    with pytest.raises(PhysposeError, match="file not found"):
        render_overlay(folder, out=tmp_path / "o.mp4", video=tmp_path / "missing.mp4", cfg=CFG)
    short = write_video(tmp_path / "short.mp4", 10, fps=SOURCE_FPS)
    with pytest.raises(PhysposeError, match="the video has"):
        render_overlay(folder, out=tmp_path / "o.mp4", video=short, cfg=CFG)
    with pytest.raises(PhysposeError, match="outside the result"):
        save_overlay_png(folder, Reconstruction.load(folder).num_frames, tmp_path / "x.png")
    # Another video than the one the result was made from, told by its size.
    other = tmp_path / "other"
    rec = Reconstruction.load(folder)
    rec.replace(meta={**rec.meta, "image_size": [IMAGE_SIZE[0] * 2, IMAGE_SIZE[1] * 2]}).save(
        other / "reconstruction.npz")
    with pytest.raises(PhysposeError, match=f"the video is {IMAGE_SIZE[0]}x{IMAGE_SIZE[1]}"):
        save_overlay_png(other, 0, tmp_path / "x.png", video=rec.meta["source"])
    # The recorded video, found by itself: a plain background, so that a run's last step
    # (its overlay) does not fail on a video changed since.
    made = render_overlay(other, out=tmp_path / "o.mp4", cfg=CFG)
    assert made.background.startswith("plain background")


def test_the_ground_force_is_an_arrow_from_each_loaded_foot(tmp_path):
    from physpose.render.overlay import FORCE_M_PER_BW, _scene, _view_camera

    rec = make_reconstruction(num_frames=20)
    rec.save(tmp_path / "f" / "reconstruction.npz")
    rec.replace(grf_physics=None, cop_physics=None, torques_physics=None).save(
        tmp_path / "n" / "reconstruction.npz")

    def view(folder, t):
        png = cv2.imread(str(save_overlay_png(tmp_path / folder, t, tmp_path / "f.png", cfg=CFG)))
        return png[:, IMAGE_SIZE[0]:]

    def green(image):
        return np.abs(image.astype(int) - FORCE_COLOR).sum(axis=-1) < 40

    # Frame 15: the left foot is in the air (no arrow), the right one carries the body weight.
    scene = _scene(rec, IMAGE_SIZE)
    arrows = scene.force_arrows[15]
    assert np.isnan(arrows[0]).all()
    weight = rec.grf_physics[15, :2, 2].sum()  # the synthetic walk's feet share its weight
    np.testing.assert_allclose(arrows[1, 1] - arrows[1, 0],
                               rec.grf_physics[15, 1] / weight * FORCE_M_PER_BW, atol=1e-9)
    k, t_w2c = _view_camera(scene, 15, CFG)
    (x, y), _ = project(k, t_w2c, arrows[1].mean(axis=0))  # the arrow's middle
    image = view("f", 15)
    assert green(image[round(y) - 2:round(y) + 3, round(x) - 2:round(x) + 3]).any()
    assert not green(view("n", 15)).any()  # without forces, no arrow and no legend row


def test_the_overlay_of_slow_motion_footage_plays_at_the_footage_pace(result_with_video,
                                                                        tmp_path):
    folder, _, indices = result_with_video
    rec = Reconstruction.load(folder / "reconstruction.npz")
    slowed = rec.replace(fps=4 * rec.fps, meta={**rec.meta, "slow_motion": 4.0})
    slowed.save(tmp_path / "slow" / "reconstruction.npz")
    made = render_overlay(tmp_path / "slow", out=tmp_path / "o.mp4", cfg=CFG)
    cap = cv2.VideoCapture(str(made.path))
    # The result runs on the real clock (4x the frame rate); its video at the footage's rate.
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(FPS)
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == len(indices)
