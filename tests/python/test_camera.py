"""metadata.json's camera (intrinsics with the crop's offset, camera-to-world pose) against the renderer's
own geometry: the ground truth's two depths (range along the ray, z along the axis) give each pixel's ray
angle independently of the intrinsics; world points land on the scene's known surfaces; points project back
onto the pixel centres."""
import numpy as np
import pytest

import spadgen


@pytest.fixture(scope="module")
def sweep(sweep_run):
    return spadgen.open_run(sweep_run)


@pytest.fixture(scope="module")
def posed(make_run):
    return spadgen.open_run(make_run("posed"))


def test_intrinsics_from_the_camera_model(sweep):
    cam = sweep.metadata["camera"]
    scene = sweep.metadata["resolved_scene"]["camera"]
    f = scene["focal_length_mm"] * 1e-3 / (scene["pixel_pitch_um"] * 1e-6)
    x0, y0 = sweep.crop[:2]
    # Sensor pixel x spans [x, x + 1) with the optical axis at width / 2; the image's pixel 0 is sensor x0.
    expected = [[f, 0, 1024 / 2 - 0.5 - x0], [0, f, 500 / 2 - 0.5 - y0], [0, 0, 1]]
    np.testing.assert_allclose(sweep.intrinsics, expected, rtol=1e-12)
    assert cam["focal_length_m"] == pytest.approx(0.025) and cam["pixel_pitch_m"] == pytest.approx(9.4e-6)


@pytest.mark.parametrize("which", ["sweep", "posed"])
def test_ray_angles_match_range_over_z(which, sweep, posed):
    run = {"sweep": sweep, "posed": posed}[which]
    gt, hit = run.ground_truth, run.hit()
    rays = spadgen.pixel_rays(run.intrinsics, run.width, run.height)
    cos_truth = gt["z"][hit].astype(np.float64) / gt["range"][hit]
    # float32 depths: about 1e-7; half a pixel off in cx or cy would be 5e-6 (posed) to 2e-5 (sweep).
    np.testing.assert_allclose(cos_truth, rays[..., 2][hit], rtol=5e-7)
    shifted = run.intrinsics.copy()
    shifted[0, 2] += 0.5
    assert np.abs(cos_truth / spadgen.pixel_rays(shifted, run.width, run.height)[..., 2][hit] - 1).max() > 2e-6


def test_points_project_back_onto_pixel_centres(sweep, posed):
    for run in (sweep, posed):
        hit = run.hit()
        u, v = np.meshgrid(np.arange(run.width), np.arange(run.height))
        for frame, to_camera in (("camera", None), ("world", run.world_to_camera)):
            pts = run.points(frame)
            assert pts.shape == (run.height, run.width, 3) and pts.dtype == np.float64
            assert np.isnan(pts[~hit]).all() and np.isfinite(pts[hit]).all()
            uv = spadgen.project(pts, run.intrinsics, to_camera)
            np.testing.assert_allclose(uv[hit], np.stack([u, v], -1)[hit], atol=1e-6)
        # Range along the ray and z along the axis give the same points.
        np.testing.assert_allclose(run.points(kind="z")[hit], run.points()[hit], rtol=1e-6)
        np.testing.assert_allclose(np.linalg.norm(run.points()[hit], axis=-1), run.depth()[hit], rtol=1e-12)
    assert not sweep.hit().all()  # the sweep's crop reaches past the sphere


def test_pose_puts_points_on_the_scene_surfaces(posed):
    M = posed.camera_to_world
    R = M[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    scene = posed.metadata["resolved_scene"]["camera"]
    position, look_at = np.array(scene["position_m"]), np.array(scene["look_at_m"])
    np.testing.assert_allclose(M[:3, 3], position)
    np.testing.assert_allclose(R[:, 2], (look_at - position) / np.linalg.norm(look_at - position), atol=1e-12)
    # multi_object.gltf: the plate's front face at world z = -0.45 m for x < 0 (its 2 mm edge face at x = 0
    # shows from this camera), the sphere of radius 0.1 m around (0, 0, -0.85).
    mesh, _ = posed.labels()
    p = posed.points("world")
    assert (mesh == 0).sum() > 500 and (mesh == 1).sum() > 500
    plate = p[mesh == 0]
    front = np.abs(plate[:, 2] + 0.45) < 2e-5
    edge = (np.abs(plate[:, 0]) < 2e-5) & (plate[:, 2] <= -0.45 + 2e-5) & (plate[:, 2] >= -0.452 - 2e-5)
    assert (front | edge).all() and front.sum() > 0.9 * len(plate)
    sphere = p[mesh == 1]
    np.testing.assert_allclose(np.linalg.norm(sphere - [0, 0, -0.85], axis=1), 0.1, atol=2e-5)


def test_point_cloud_keeps_the_hits(sweep):
    cloud = sweep.point_cloud("world")
    assert cloud.shape == (int(sweep.hit().sum()), 3)
    np.testing.assert_allclose(cloud, sweep.points("world")[sweep.hit()])
    depth = spadgen.depth_to_points(np.full((2, 3), 2.0), np.array([[1.0, 0, 1], [0, 1.0, 0.5], [0, 0, 1]]))
    np.testing.assert_allclose(depth[1, 1], 2.0 * np.array([0, 0.5, 1]) / np.linalg.norm([0, 0.5, 1]))
