"""HumanML3D 263-d features: round trip, normalisation, layout, rotations, errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from motok_robot.errors import InputError
from motok_robot.motion import features as F
from motok_robot.motion import rotations as R
from motok_robot.motion import skeleton as sk
from motok_robot.motion import synthetic

CLIPS = {
    "walk": lambda: synthetic.walking_clip(120),
    "stand": lambda: synthetic.standing_clip(30),
    "random": lambda: synthetic.random_poses(40, seed=3, scale=1.25),
}


@pytest.fixture(scope="module", params=sorted(CLIPS))
def clip(request):
    return CLIPS[request.param]()


# ----------------------------------------------------------------------------- round trip


def test_round_trip_matches_normalised_input_to_a_millimetre(clip):
    feats = F.features_from_joints(clip)
    assert feats.shape == (len(clip) - 1, 263) and feats.dtype == np.float32
    assert np.all(np.isfinite(feats))
    rec = F.joints_from_features(feats)
    norm = F.normalise_joints(clip)
    assert rec.shape == (len(clip) - 1, 22, 3)
    err = np.abs(rec - norm[:-1]).max()
    assert err < 1e-3
    assert err < 1e-5  # float32 rounding only


def test_round_trip_long_turning_clip_does_not_drift():
    clip = synthetic.walking_clip(600, turn_rate=1.0, speed=1.5)  # 30 s, almost five turns
    rec = F.joints_from_features(F.features_from_joints(clip))
    assert np.abs(rec - F.normalise_joints(clip)[:-1]).max() < 1e-4


def test_joints_from_features_is_batched():
    a = F.features_from_joints(synthetic.walking_clip(30))
    b = F.features_from_joints(synthetic.random_poses(30, seed=1))
    batch = np.stack([a, b])[None]  # [1, 2, 29, 263]
    out = F.joints_from_features(batch)
    assert out.shape == (1, 2, 29, 22, 3)
    np.testing.assert_allclose(out[0, 0], F.joints_from_features(a), atol=1e-6)
    np.testing.assert_allclose(out[0, 1], F.joints_from_features(b), atol=1e-6)


# ----------------------------------------------------------------------------- normalisation


def test_normalise_joints_canonical_bones_floor_origin_facing(clip):
    norm = F.normalise_joints(clip)
    parents = list(sk.PARENTS[1:])
    lengths = np.linalg.norm(norm[:, 1:] - norm[:, parents], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(sk.BONE_LENGTHS[1:], lengths.shape), atol=1e-9)
    assert norm[..., 2].min() == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(norm[0, 0, :2], 0.0, atol=1e-12)
    across = (norm[0, 2] - norm[0, 1]) + (norm[0, 17] - norm[0, 16])
    forward = np.cross([0.0, 0.0, 1.0], across)
    assert np.arctan2(forward[1], forward[0]) == pytest.approx(0.0, abs=1e-9)
    # bone directions come from the data (up to the global yaw turn)
    src_dirs = clip[:, 1:] - clip[:, parents]
    new_dirs = norm[:, 1:] - norm[:, parents]
    cos_src = np.einsum("tbi,tbi->tb", src_dirs[:, :-1], src_dirs[:, 1:]) / (
        np.linalg.norm(src_dirs[:, :-1], axis=-1) * np.linalg.norm(src_dirs[:, 1:], axis=-1))
    cos_new = np.einsum("tbi,tbi->tb", new_dirs[:, :-1], new_dirs[:, 1:]) / (
        np.linalg.norm(new_dirs[:, :-1], axis=-1) * np.linalg.norm(new_dirs[:, 1:], axis=-1))
    np.testing.assert_allclose(cos_new, cos_src, atol=1e-9)
    np.testing.assert_allclose(F.normalise_joints(norm), norm, atol=1e-9)  # idempotent


def test_normalise_rescales_a_big_person_and_their_stride():
    clip = synthetic.walking_clip(60)
    big = clip * 1.3  # everything 30 % larger: bones and the path
    np.testing.assert_allclose(F.normalise_joints(big), F.normalise_joints(clip), atol=1e-9)


def test_features_invariant_to_placement_and_heading():
    clip = synthetic.walking_clip(60)
    turn = R.rotation_about_axis(2.1, 2)
    moved = clip @ turn.T + np.array([3.0, -1.0, 0.4])
    np.testing.assert_allclose(F.features_from_joints(moved), F.features_from_joints(clip), atol=2e-5)


def test_zero_length_bone_gets_a_direction_instead_of_nan():
    clip = synthetic.walking_clip(20)
    clip[:, sk.JOINT_INDEX["left_collar"]] = clip[:, sk.JOINT_INDEX["spine3"]]  # collar missing in the source
    clip[5, sk.JOINT_INDEX["head"]] = clip[5, sk.JOINT_INDEX["neck"]]  # one bad frame
    norm = F.normalise_joints(clip)
    assert np.all(np.isfinite(norm))
    head_dir = norm[:, 15] - norm[:, 12]
    np.testing.assert_allclose(head_dir[5], head_dir[4], atol=1e-12)  # nearest frame with a head bone
    collar = norm[:, sk.JOINT_INDEX["left_collar"]] - norm[:, sk.JOINT_INDEX["spine3"]]
    np.testing.assert_allclose(np.linalg.norm(collar, axis=-1), sk.BONE_LENGTHS[sk.JOINT_INDEX["left_collar"]])
    assert np.all(collar[:, 1] > 0)  # rest direction turned with the body: still on the left at frame 0 facing +x
    assert np.all(np.isfinite(F.features_from_joints(clip)))


# ----------------------------------------------------------------------------- reference pipeline


def _reference_features(g: np.ndarray) -> np.ndarray:
    """HumanML3D's process_file steps after normalisation, written with quaternions (y-up,
    already on the floor, at the origin and facing +z) to cross-check the angle-based code."""
    t_count = len(g)
    # inverse kinematics facing: HumanML3D unpacks (l_hip, r_hip) = (2, 1)
    across = (g[:, 1] - g[:, 2]) + (g[:, 17] - g[:, 16])
    across /= np.linalg.norm(across, axis=-1, keepdims=True)
    forward = np.cross(np.array([[0.0, 1.0, 0.0]]), across)
    forward = gaussian_filter1d(forward, 20, axis=0, mode="nearest")
    forward /= np.linalg.norm(forward, axis=-1, keepdims=True)
    root_quat = R.quat_between(forward, np.array([[0.0, 0.0, 1.0]]))
    root_quat[0] = [1.0, 0.0, 0.0, 0.0]
    quats = np.zeros((t_count, 22, 4))
    quats[:, 0] = root_quat
    for chain in sk.KINEMATIC_CHAINS:
        parent_q = root_quat
        for a, b in zip(chain[:-1], chain[1:]):
            u = np.broadcast_to(F.IK_REST_DIRECTIONS[b], (t_count, 3))
            v = g[:, b] - g[:, a]
            swing = R.quat_between(u, v / np.linalg.norm(v, axis=-1, keepdims=True))
            local = R.quat_mul(R.quat_inverse(parent_q), swing)
            quats[:, b] = local
            parent_q = R.quat_mul(parent_q, local)
    rot6d = R.quat_to_cont6d(quats)
    r_rot = quats[:, 0]
    vel = R.quat_rotate(r_rot[1:], g[1:, 0] - g[:-1, 0])
    r_vel = R.quat_mul(r_rot[1:], R.quat_inverse(r_rot[:-1]))
    rel = g.copy()
    rel[..., 0] -= g[:, :1, 0]
    rel[..., 2] -= g[:, :1, 2]
    ric = R.quat_rotate(r_rot[:, None], rel)
    local_vel = R.quat_rotate(r_rot[:-1, None], g[1:] - g[:-1])
    feet_l = (np.sum((g[1:, [7, 10]] - g[:-1, [7, 10]]) ** 2, -1) < 0.002).astype(float)
    feet_r = (np.sum((g[1:, [8, 11]] - g[:-1, [8, 11]]) ** 2, -1) < 0.002).astype(float)
    return np.concatenate(
        [np.arcsin(r_vel[:, 2:3]), vel[:, [0, 2]], ric[:-1, 0, 1:2], ric[:-1, 1:].reshape(t_count - 1, -1),
         rot6d[:-1, 1:].reshape(t_count - 1, -1), local_vel.reshape(t_count - 1, -1), feet_l, feet_r], axis=-1)


@pytest.mark.parametrize("name", ["walk", "stand"])
def test_features_match_quaternion_reference_pipeline(name):
    clip = CLIPS[name]()
    g = sk.yup_from_zup(F.normalise_joints(clip))
    ours = F.features_from_joints(clip)
    ref = _reference_features(g)
    np.testing.assert_allclose(ours, ref, atol=2e-5)


def test_gaussian_smooth_matches_scipy():
    x = np.random.default_rng(0).normal(size=(57, 3))
    for sigma in (0.7, 3.0, 20.0):
        np.testing.assert_allclose(F.gaussian_smooth(x, sigma), gaussian_filter1d(x, sigma, axis=0, mode="nearest"), atol=1e-12)


# ----------------------------------------------------------------------------- layout


def test_layout_root_height_ric_and_velocities():
    clip = synthetic.walking_clip(40, turn_rate=0.0, start_yaw=0.0)  # straight along +x
    norm = F.normalise_joints(clip)
    feats = F.features_from_joints(clip).astype(np.float64)
    s = F.FEATURE_SLICES
    assert sum(sl.stop - sl.start for sl in s.values()) == 263
    np.testing.assert_allclose(feats[:, s["root_height"]][:, 0], norm[:-1, 0, 2], atol=1e-6)
    # straight walk along +x (z forward in HumanML3D): planar velocity mostly forward (dim 2)
    forward = feats[:, 2]
    assert forward.mean() == pytest.approx(1.2 / 20, rel=0.05)
    assert np.abs(feats[:, 1]).max() < 0.02
    # joint heights appear unchanged in the ric block (y of HumanML3D = z of the project)
    ric = feats[:, s["ric_positions"]].reshape(-1, 21, 3)
    np.testing.assert_allclose(ric[..., 1], norm[:-1, 1:, 2], atol=1e-6)
    # vertical joint velocities are plain height differences
    vel = feats[:, s["local_velocities"]].reshape(-1, 22, 3)
    np.testing.assert_allclose(vel[..., 1], np.diff(norm[..., 2], axis=0), atol=1e-6)


def test_root_yaw_velocity_sign_and_heading():
    left = F.features_from_joints(synthetic.walking_clip(200, turn_rate=0.5))
    right = F.features_from_joints(synthetic.walking_clip(200, turn_rate=-0.5))
    # turning left (towards +y, counter-clockwise from above) gives negative values
    assert np.mean(left[20:-20, 0]) < -0.005
    assert np.mean(right[20:-20, 0]) > 0.005
    _, heading = F.root_from_features(left)
    assert heading[0] == 0.0
    # total turn over the clip: 0.5 rad/s for ~9.9 s, minus what the edge smoothing removes
    assert 3.0 < heading[-1] < 5.0


def test_foot_contacts_thresholds():
    still = F.features_from_joints(synthetic.standing_clip(10))
    assert np.all(still[:, 259:263] == 1.0)
    # the whole body glides: 5 cm per frame is above sqrt(0.002) = 4.47 cm, 4 cm is below
    for step, expected in ((0.05, 0.0), (0.04, 1.0)):
        clip = synthetic.standing_clip(4, yaw=0.0)
        clip[..., 0] += step * np.arange(4)[:, None]
        np.testing.assert_array_equal(F.features_from_joints(clip)[:, 259:263], expected)
    # walking: contacts follow the normalised foot joints' squared step length, per foot
    clip = synthetic.walking_clip(80)
    norm = F.normalise_joints(clip)
    step2 = np.sum(np.diff(norm[:, [7, 10, 8, 11]], axis=0) ** 2, axis=-1)
    contacts = F.features_from_joints(clip)[:, 259:263]
    np.testing.assert_array_equal(contacts, (step2 < 0.002).astype(np.float32))
    assert 0 < contacts.mean() < 1
    assert F.CONTACT_JOINTS == (7, 10, 8, 11)


# ----------------------------------------------------------------------------- rotations


def test_6d_rotations_reconstruct_bone_directions_as_documented():
    clip = synthetic.walking_clip(50)
    g = sk.yup_from_zup(F.normalise_joints(clip))[:-1]
    feats = F.features_from_joints(clip)
    mats = F.local_rotations_from_features(feats)  # [T, 22, 3, 3], row 0 = Q_t
    q_t = mats[:, 0]
    for chain in sk.KINEMATIC_CHAINS:
        s_prev = q_t
        for a, b in zip(chain[:-1], chain[1:]):
            s_b = s_prev @ mats[:, b]
            predicted = s_b @ F.IK_REST_DIRECTIONS[b]
            actual = g[:, b] - g[:, a]
            actual /= np.linalg.norm(actual, axis=-1, keepdims=True)
            np.testing.assert_allclose(predicted, actual, atol=1e-5)
            s_prev = s_b


def test_6d_rotations_finite_and_continuous_even_with_arm_straight_up():
    clip = synthetic.walking_clip(60)
    ls, le, lw = (sk.JOINT_INDEX[n] for n in ("left_shoulder", "left_elbow", "left_wrist"))
    # raise the left arm to point straight up (opposite to its rest direction) in frame 30
    up = np.array([0.0, 0.0, 1.0])
    clip[30, le] = clip[30, ls] + sk.BONE_LENGTHS[le] * up
    clip[30, lw] = clip[30, le] + sk.BONE_LENGTHS[lw] * up
    feats = F.features_from_joints(clip)
    assert np.all(np.isfinite(feats))
    mats = F.local_rotations_from_features(feats)
    np.testing.assert_allclose(mats @ np.swapaxes(mats, -1, -2), np.broadcast_to(np.eye(3), mats.shape), atol=1e-5)
    # away from the singular frame the rotations change little from frame to frame
    step = R.geodesic_angle(mats[:-1], mats[1:])
    smooth = np.r_[0:28, 32:len(step)]
    assert step[smooth].max() < 0.35


# ----------------------------------------------------------------------------- errors and resampling


def test_bad_shapes_name_the_expected_shape():
    with pytest.raises(InputError, match=r"\[T, 22, 3\]"):
        F.features_from_joints(np.zeros((10, 24, 3)))
    with pytest.raises(InputError, match=r"\[T, 22, 3\]"):
        F.normalise_joints(np.zeros((22, 3)))
    with pytest.raises(InputError, match=r"\[\.\.\., T, 263\]"):
        F.joints_from_features(np.zeros((5, 262)))


def test_nan_names_frame_and_joint():
    clip = synthetic.walking_clip(10)
    clip[7, sk.JOINT_INDEX["right_elbow"], 1] = np.nan
    with pytest.raises(InputError, match=r"frame 7, joint 19 \(right_elbow\)"):
        F.features_from_joints(clip)
    feats = F.features_from_joints(synthetic.walking_clip(10))
    feats[3, 100] = np.inf
    with pytest.raises(InputError, match="frame 3, dim 100"):
        F.joints_from_features(feats)


def test_too_few_frames_and_wrong_fps():
    with pytest.raises(InputError, match="at least 2"):
        F.features_from_joints(synthetic.walking_clip(1))
    with pytest.raises(InputError, match="resample"):
        F.features_from_joints(synthetic.walking_clip(10), fps=30)


def test_resample_linear_interpolation():
    clip = synthetic.walking_clip(7, fps=30)
    out = F.resample(clip, 30, 20)
    assert out.shape == (5, 22, 3)  # 0.2 s at 20 fps: frames at 0, .05, .1, .15, .2 s
    np.testing.assert_allclose(out[0], clip[0])
    np.testing.assert_allclose(out[1], 0.5 * clip[1] + 0.5 * clip[2])  # 0.05 s = source frame 1.5
    np.testing.assert_allclose(out[4], clip[6])
    up = F.resample(clip[:2], 10, 20)
    np.testing.assert_allclose(up[1], 0.5 * (clip[0] + clip[1]))
    with pytest.raises(InputError, match="positive"):
        F.resample(clip, 0, 20)


# ----------------------------------------------------------------------------- dataset checker


def test_roundtrip_checker_on_a_tiny_prepared_folder(tmp_path, capsys):
    from motok_robot.motion import roundtrip

    (tmp_path / "joints").mkdir()
    (tmp_path / "features").mkdir()
    for i, clip in enumerate([synthetic.walking_clip(30), synthetic.standing_clip(12)]):
        norm = F.normalise_joints(clip).astype(np.float32)
        np.save(tmp_path / "joints" / f"c{i}.npy", norm)
        np.save(tmp_path / "features" / f"c{i}.npy", F.features_from_joints(norm))
    out = tmp_path / "report.json"
    assert roundtrip.main([str(tmp_path), "--json", str(out)]) == 0
    assert "2 clips checked" in capsys.readouterr().out
    # a clip whose features do not match its joints fails the check
    bad = F.features_from_joints(synthetic.walking_clip(30, speed=2.0))
    np.save(tmp_path / "features" / "c0.npy", bad)
    assert roundtrip.main([str(tmp_path)]) == 1
    assert roundtrip.main([str(tmp_path / "nothing")]) == 2


def test_numpy_modules_do_not_import_torch():
    import subprocess
    import sys

    code = ("import sys, motok_robot.motion, motok_robot.motion.features, motok_robot.motion.metrics, "
            "motok_robot.motion.render, motok_robot.motion.roundtrip, motok_robot.motion.synthetic, "
            "motok_robot.motion.rotations; print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
